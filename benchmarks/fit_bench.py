"""Benchmark of `fitting.fit`: eta, mu and C on 10 traces of the paper's 21-bead chain.

    python benchmarks/fit_bench.py [--out fit_bench.json] [--traces 10]

Data: 10 impact velocities log-spaced over 0.05-0.5 m/s, contacts 6 and 11 and the wall,
2 ms at 1 us sampling, eta = 2 us, mu = 0.19, mu* = 0.02, white noise of 0.5 % of each
file's largest force (simulated with twice finer steps than the fit's). Measured:

- `fit_s`: one call of `fitting.fit(files, ("eta", "mu", "C"))` from the data-derived
  start, everything included (problem set-up, XLA compilation, optimisation, covariance);
- `compile_and_run_s` / `run_s`: the same optimisation through `fitting.fit_datasets`,
  first call (compilation included) and second call (compiled), so `run_s` is the
  optimisation alone;
- the estimates, standard errors and z-scores against the truth.

`benchmark_fit()` returns the same dict for other scripts (e.g. `benchmarks/run.py`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

TRUTH = {"eta": 2e-6, "mu": 0.19, "mu_star": 0.02}


def benchmark_files(n_traces: int = 10, *, t_end_s: float = 2e-3, noise_fraction: float = 0.005,
                    seed: int = 0):
    """The benchmark's traces (see the module docstring): (files, truth of eta, mu, C (SI),
    seconds to simulate them)."""
    from fitting.parameters import bare_speed_constant
    from fitting.synthetic import paper_setups, synthetic_traces

    velocities = np.geomspace(0.05, 0.5, n_traces)
    setups = paper_setups(velocities, eta_s=TRUTH["eta"], mu=TRUTH["mu"], mu_star=TRUTH["mu_star"])
    began = time.perf_counter()
    clean = synthetic_traces(setups, contacts=(6, 11), t_end_s=t_end_s)
    sigma = [noise_fraction * max(np.max(v) for v in f.channels.values()) for f in clean]
    files = synthetic_traces(setups, contacts=(6, 11), t_end_s=t_end_s, noise_std_n=sigma, seed=seed)
    truth = np.array([TRUTH["eta"], TRUTH["mu"],
                      float(bare_speed_constant(setups[0])) * (1 + TRUTH["mu_star"]) ** (1 / 3)])
    return files, truth, time.perf_counter() - began


def benchmark_fit(n_traces: int = 10, *, t_end_s: float = 2e-3, noise_fraction: float = 0.005,
                  seed: int = 0) -> dict:
    """Time a fit of eta, mu, C on `n_traces` synthetic traces; returns a JSON-ready dict."""
    import fitting

    files, truth, data_s = benchmark_files(n_traces, t_end_s=t_end_s, noise_fraction=noise_fraction,
                                           seed=seed)

    began = time.perf_counter()
    result = fitting.fit(files, ("eta", "mu", "C"), progress=False, throw=False)
    fit_s = time.perf_counter() - began
    values = np.array([result.values[k] for k in ("eta", "mu", "C")])
    stderr = np.array([result.stderr[k] for k in ("eta", "mu", "C")])

    problem = result.problem
    data = problem.data_vector()[None]
    began = time.perf_counter()
    fitting.fit_datasets(problem, data)
    first_s = time.perf_counter() - began
    began = time.perf_counter()
    fitting.fit_datasets(problem, data)
    run_s = time.perf_counter() - began
    return {
        "case": f"eta, mu, C on {n_traces} traces of 21 beads (contacts 6, 11, wall; "
                f"{t_end_s * 1e3:g} ms at 1 us; noise {noise_fraction:.1%} of full scale)",
        "n_residuals": int(problem.n_residuals),
        "time_step_s": [g.grid.dt_s for g in problem.groups],
        "steps_per_trace": [g.grid.n_steps for g in problem.groups],
        "data_generation_s": data_s,
        "fit_s": fit_s,
        "compile_and_run_s": first_s,
        "run_s": run_s,
        "iterations": int(result.n_steps),
        "converged": bool(result.converged),
        "reduced_chi2": float(result.reduced_chi2),
        "truth": dict(zip(("eta", "mu", "C"), truth.tolist())),
        "values": dict(zip(("eta", "mu", "C"), values.tolist())),
        "stderr": dict(zip(("eta", "mu", "C"), stderr.tolist())),
        "z_scores": dict(zip(("eta", "mu", "C"), ((values - truth) / stderr).tolist())),
        "machine": machine_info(),
    }


def machine_info() -> dict:
    """The cores, the processor and the 1-minute load average when a benchmark ends."""
    return {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
            "load_average_1min": os.getloadavg()[0]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="fit_bench.json", help="JSON output [fit_bench.json]")
    parser.add_argument("--traces", type=int, default=10, help="number of traces [10]")
    args = parser.parse_args(argv)
    from hertzchain.atomic import write_json

    result = benchmark_fit(args.traces)
    write_json(args.out, result)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
