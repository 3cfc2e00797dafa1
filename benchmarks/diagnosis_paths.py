"""One evaluation of the diagnosis's model on each of its code paths.

The diagnosis's forward model (`fitting.effects.effects_forward_model`: every candidate effect
applied to the chain) runs on three paths: `solve` under `vmap` (a `ForwardModel` without its
`KernelForm`), the batched kernel with compliant sensor beads (`record_batched(...,
compliant_sensors=)`: the C++ kernel's sensor library, or the JAX kernel where the C++ one is
off, `HERTZCHAIN_NATIVE=0`; `runs_cpp_kernel` says which) and the C++ kernel's twin with rigid
sensor beads (with or without the dashpot effect; the JAX kernel where the C++ one is off). This times the residuals with a 6-column and with the whole Jacobian on
each, for 21 beads of the paper's chain, 4 shots (0.1-0.5 m/s), contacts 5, 10 and 15 read
by embedded sensors; damping, sensors' Eq. 4 and the dashpot on, and the same with track
friction.

    python benchmarks/diagnosis_paths.py --out benchmarks/results/diagnosis_paths
    HERTZCHAIN_NATIVE=0 python benchmarks/diagnosis_paths.py --out DIR   # the JAX kernel alone

Writes `paths.json`: per case and path, the first call (compile included) and the median of 5
more, s, the largest difference of the residuals from `solve`'s (relative to their largest),
and the machine's 1-minute load average before and after.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time
from pathlib import Path

import numpy as np

from fitting import effects as fx
from fitting.fit import initial_values, make_problem
from fitting.hidden import hidden_effect_traces
from fitting.model import Problem, residuals_and_jacobian
from fitting.parameters import ParameterInstance, get_spec
from hertzchain.io import atomic

N_BEADS = 21
EXTRAS = ("eta_s", "dashpot_n_s_m", "mu", "preload_n", "preload_seen", "sensor_beta", "sensor_rate",
          "sensor_coupling", "wall_softening")
VALUES = {"eta_s": 3e-7, "dashpot_n_s_m": 0.3, "sensor_beta": 0.2, "sensor_rate": 0.3, "preload_n": 0.5,
          "preload_seen": 0.5}


def _problems(files, friction: bool):
    """(solve, batched kernel, C++ twin) problems and the point x: compliance and dashpot on for
    the first two; the twin's sensors rigid (coupling 0, where it is exact)."""
    forward = fx.effects_forward_model(N_BEADS, plastic=False)
    seed = make_problem(files, ("eta_s", "C", "striker_velocity_m_s"), forward=forward)
    extra = tuple(ParameterInstance(get_spec(fx.PREFIX + name), label=name) for name in EXTRAS)

    def problem(model):
        return Problem(seed.experiments, tuple(seed.instances) + extra, seed.base_setups, model)

    paths = {"solve_vmap": problem(dataclasses.replace(forward, kernel=None)), "batched_kernel": problem(forward),
             "cpp_twin": problem(fx.effects_forward_model(N_BEADS, plastic=False, compliant_sensors=False))}
    x = np.concatenate([initial_values(seed), np.zeros(len(extra))])
    labels = paths["solve_vmap"].labels
    for name, value in VALUES.items():
        x[labels.index(name)] = value
    x[labels.index("mu")] = 0.1 if friction else 0.0
    compliant = x.copy()
    compliant[labels.index("sensor_coupling")] = 0.5
    return paths, {"solve_vmap": compliant, "batched_kernel": compliant, "cpp_twin": x}, labels


def _time(problem, x, columns):
    began = time.perf_counter()
    r, _ = residuals_and_jacobian(problem, x, columns)
    first = time.perf_counter() - began
    runs = []
    for _ in range(5):
        began = time.perf_counter()
        residuals_and_jacobian(problem, x, columns)
        runs.append(time.perf_counter() - began)
    return r, {"first_s": first, "median_s": statistics.median(runs), "runs_s": runs}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "diagnosis_paths"))
    args = parser.parse_args(argv)
    files = hidden_effect_traces((), n_beads=N_BEADS, velocities_m_s=(0.1, 0.2, 0.3, 0.5), contacts=(5, 10, 15),
                                 seed=2, t_end_s=1.5e-3)
    result = {"load_before": os.getloadavg()[0], "cases": {}}
    for friction in (False, True):
        paths, points, labels = _problems(files, friction)
        six = [labels.index(name) for name in ("eta_s", "sensor_rate", "sensor_beta")] + [0, 1, 2]
        case = {}
        reference = None
        for name, problem in paths.items():
            entry = {"runs_cpp_kernel": problem.simulates_natively()}
            for label, columns in (("six_columns", six), ("all_columns", None)):
                r, entry[label] = _time(problem, points[name], columns)
                print(f"{'friction' if friction else 'damped'} {name} {label}: {entry[label]['median_s'] * 1e3:.1f} ms "
                      f"(first call {entry[label]['first_s']:.1f} s)", flush=True)
            if name == "solve_vmap":
                reference = r
            elif name == "batched_kernel":
                entry["residuals_difference_over_largest"] = float(np.max(np.abs(r - reference))
                                                                   / np.max(np.abs(reference)))
            case[name] = entry
        result["cases"]["friction" if friction else "damped"] = case
    result["load_after"] = os.getloadavg()[0]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic.write_json(out / "paths.json", result)


if __name__ == "__main__":
    main()
