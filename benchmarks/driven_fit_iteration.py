"""Time one evaluation of a driven fit on measured data: the residuals, and the residuals with
their Jacobian in the five fitted parameters, of Lydon et al.'s two-bead sweep (901
frequencies x 36 drive levels, `examples/lydon2015/two_bead_bending.toml`), and the same on
the fit's coarse grid (every 3rd frequency of every 7th level).

    python benchmarks/driven_fit_iteration.py --data-dir DATA/lydon-2015 --out FILE.json
    HERTZCHAIN_NATIVE=0 python benchmarks/driven_fit_iteration.py ...   # the JAX kernel

The kernel is whichever `lockin_grid` runs here (`kernel` in the JSON: "fused" or "jax").
Each figure is the best of `--repeats` calls after a first, compiling one (stored too), at the
parameters the fit ends at; `residuals_sum_of_squares` lets two runs be compared.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import hertzchain  # noqa: F401  (float64)
from fitting.driven import lockin_fit as driven
from fitting.driven.experiment import load_driven_experiment
from hertzchain.driven import fused
from hertzchain.io.atomic import write_json

HERE = Path(__file__).resolve().parent
# where the two-bead fit ends (examples/lydon2015/results/two_bead_fit/fit.json), eta_s = 0
X = np.array([2104.99, 4966.86, 0.16747, 685.64, 1.26213, 0.0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data-dir", required=True, type=Path, help="the lydon-2015 folder")
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    experiment = load_driven_experiment(HERE.parent / "examples/lydon2015/two_bead_bending.toml", args.data_dir)
    rows = np.nonzero(experiment.fit_mask)[0]
    models = {"full": driven.DrivenModel(experiment),
              "coarse": driven.DrivenModel(experiment, rows=rows[::driven.COARSE_ROW_STRIDE],
                                           levels=np.arange(36)[::driven.COARSE_LEVEL_STRIDE])}
    result = {"kernel": "fused" if fused.runs("velocity") else "jax", "cpus": os.cpu_count(),
              "load_average_before": os.getloadavg()[0], "x": X.tolist(), "grids": {}}
    for name, model in models.items():
        entry = {"points": int(model.measured.size)}
        for what, call in (("residuals", lambda: model.residuals(X)),
                           ("residuals_and_jacobian_5", lambda: model.linearize(X, [0, 1, 2, 3, 4]))):
            began = time.perf_counter()
            out = call()
            entry[f"{what}_first_s"] = time.perf_counter() - began
            times = []
            for _ in range(args.repeats):
                began = time.perf_counter()
                call()
                times.append(time.perf_counter() - began)
            entry[f"{what}_s"] = min(times)
            r = out if what == "residuals" else out[0]
            entry["residuals_sum_of_squares"] = float(r @ r)
        entry["jacobian_over_residuals"] = entry["residuals_and_jacobian_5_s"] / entry["residuals_s"]
        result["grids"][name] = entry
    result["load_average_after"] = os.getloadavg()[0]
    write_json(args.out, result)
    print(result)


if __name__ == "__main__":
    main()
