"""The driven candidates (`fitting.driven.candidates`) on the single bead, in one command:

    python examples/lydon2015/diagnose_laws.py --data-dir ../shared/data/real/lydon-2015
        [--out examples/lydon2015/results/single_bead_diagnosis_laws] [--max-steps 20]

Each candidate law is fitted on the bending run (2013-07-03 10:29) with the precompression held
at the stated 4.5 N and the drive scale at its calibration prior, and predicts the tongue
(09:28) and the 6850 Hz loop (07-04) at their calibration. Writes `diagnosis.json` (every
candidate's constants, measurements, gaps, the verdict, the load average at the start and the
wall time) and `diagnosis.png` (each target's measured value beside every candidate's);
`--plot-only` redraws the figure from the stored JSON. The micro-slip candidate (slow: its
sliders run the JAX kernel) is run on its own, `--only micro_slip_supports --name micro_slip`;
the pairs likewise. `--with-tongue` fits the free-preload candidates on the bending and the
tongue together (its fundamental below onset and its thresholds) and predicts the loop.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
from pathlib import Path

import numpy as np

from fitting.driven.candidates import (
    CANDIDATES,
    FREE_PRELOAD_CANDIDATES,
    FREE_PRELOAD_START_N,
    SLOW_CANDIDATES,
    diagnose_laws,
    fit_candidate,
    fit_candidate_jointly,
    scores,
)
from fitting.driven.experiment import load_driven_experiment
from hertzchain.io.atomic import json_ready, save_figure, write_json

HERE = Path(__file__).resolve().parent
LABELS = {"bending_misfit_median": "bending misfit (median)", "shift_points": "shift, model - data",
          "peak_ratio": "peak per nm top/lowest", "tongue_tip_amplitude": "tongue tip, model/data",
          "tongue_tip_frequency": "tongue tip f, model/data - 1", "loop_onset_up": "loop onset up, model/data"}
AIMS = {"bending_misfit_median": 0.03, "shift_points": 0.0, "tongue_tip_amplitude": 1.0,
        "tongue_tip_frequency": 0.0, "loop_onset_up": 1.0}


def plot(result: dict, path: Path) -> None:
    """One panel per target: every candidate's value (missing: no period doubling found), the
    measured value (or the target) as a line."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    entries = result["candidates"]
    names = [e["name"] for e in entries]
    figure, axes = plt.subplots(2, 3, figsize=(13, 8))
    for ax, key in zip(axes.ravel(), LABELS):
        values = [scores(e)[key][0] for e in entries]
        shown = [np.nan if v is None else v for v in values]
        ax.bar(range(len(names)), shown, color=["C3" if scores(e)[key][1] else "C0" for e in entries])
        aim = entries[0]["bending"]["measured_peak_ratio"] if key == "peak_ratio" else AIMS[key]
        ax.axhline(aim, color="k", lw=1)
        for i, v in enumerate(values):
            if v is None:
                ax.text(i, 0.05, "none found", ha="center", va="bottom", rotation=90, fontsize=8,
                        transform=ax.get_xaxis_transform())
        ax.set_xticks(range(len(names)), names, rotation=35, ha="right", fontsize=8)
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.set_title(LABELS[key], fontsize=10)
    figure.suptitle("single bead, precompression 4.5 N: each law fitted on the bending, predicting the rest "
                    "(red: within target; line: data/target)", fontsize=10)
    figure.tight_layout()
    save_figure(figure, path, dpi=110)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", required=True)
    parser.add_argument("--out", default=str(HERE / "results" / "single_bead_diagnosis_laws"))
    parser.add_argument("--max-steps", type=int, default=20)
    parser.add_argument("--level-stride", type=int, default=1, help="fit every k-th drive level (all are reported)")
    parser.add_argument("--name", default="diagnosis", help="the result files' name (NAME.json, NAME.png)")
    parser.add_argument("--plot-only", action="store_true", help="redraw NAME.png from the stored NAME.json")
    parser.add_argument("--only", nargs="*", help="candidate names (default: every one of CANDIDATES; the base "
                        "is always fitted; SLOW_CANDIDATES only when named)")
    parser.add_argument("--with-tongue", action="store_true", help="fit FREE_PRELOAD_CANDIDATES (or --only of them "
                        "and of SLOW_CANDIDATES; free_preload always) on the bending and the tongue together "
                        "(fit_candidate_jointly), predict the loop")
    parser.add_argument("--start-precompression", type=float, default=FREE_PRELOAD_START_N,
                        help="N: with --with-tongue, where a freed static force starts (default "
                        f"{FREE_PRELOAD_START_N})")
    args = parser.parse_args(argv)
    if args.start_precompression <= 0:
        parser.error(f"--start-precompression must be > 0 N, got {args.start_precompression}.")
    out = Path(args.out)
    if args.plot_only:
        plot(json.loads((out / f"{args.name}.json").read_text()), out / f"{args.name}.png")
        return
    load = os.getloadavg()[0]
    experiment = load_driven_experiment(HERE / "single_bead_joint.toml", args.data_dir)
    if args.with_tongue:
        chosen = [c for c in FREE_PRELOAD_CANDIDATES + SLOW_CANDIDATES if (c in FREE_PRELOAD_CANDIDATES and not args.only)
                  or c.name in (args.only or ()) or c is FREE_PRELOAD_CANDIDATES[0]]
    else:
        chosen = [c for c in CANDIDATES + SLOW_CANDIDATES if (c in CANDIDATES and not args.only)
                  or c.name in (args.only or ()) or c.name == CANDIDATES[0].name]
    result = diagnose_laws(experiment, chosen, level_stride=args.level_stride, max_steps=args.max_steps,
                           fit=functools.partial(fit_candidate_jointly, start_precompression_n=args.start_precompression)
                           if args.with_tongue else fit_candidate)
    result["load_average_at_start"] = load
    result["arguments"] = {"max_steps": args.max_steps, "level_stride": args.level_stride, "only": args.only,
                           "name": args.name, "with_tongue": args.with_tongue,
                           "start_precompression_n": args.start_precompression}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / f"{args.name}.json", json_ready(result))
    plot(result, out / f"{args.name}.png")


if __name__ == "__main__":
    main()
