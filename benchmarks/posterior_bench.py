"""Benchmark of `fitting.posterior`: eta, mu, C with the lab's tolerances on 10 traces of
the paper's 21-bead chain (the data of `benchmarks/fit_bench.py`).

    python benchmarks/posterior_bench.py [--out benchmarks/results/posterior_bench/latest.json] [--traces 10]
        [--chains 4] [--warmup 100] [--draws 200]

Measured:

- `posterior`: NUTS on eta, mu, C and the three sensors' gains with a 2 % prior each
  (`sensor_gain=+-2%`): time of the MAP fit, warmup and sampling (wall, and the process's
  CPU seconds: on shared cores the wall time is mostly waiting), gradient evaluations,
  seconds per effective sample, R-hat, ESS, divergences, each parameter's posterior
  against the truth and against the Laplace approximation, and the sds next to the
  noise-only standard errors (how much the gain tolerances widen eta, mu, C);
- `bead_youngs_prior`: the Laplace (MAP-fit) standard errors of eta, mu, C when the only
  tolerance is the beads' Young's modulus, 203 +- 4 GPa (the paper's): C sets the
  bead-bead stiffness, so the modulus moves only the wall's and the striker's contacts
  relative to it, and C widens by much less than the 2 % a modulus alone would suggest.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fit_bench import benchmark_files, machine_info  # noqa: E402

PARAMS = ("eta_s", "mu", "C")
GAIN_PRIOR = "sensor_gain=+-2%"
YOUNGS_PRIOR = "bead_youngs_pa=203GPa+-4GPa"


def benchmark_posterior(n_traces: int = 10, *, chains: int = 4, warmup: int = 100, draws: int = 200,
                        seed: int = 0) -> dict:
    """Run the benchmark (see the module docstring); returns a JSON-ready dict."""
    import jax

    import fitting
    from fitting.fit import FitWarning
    from fitting.parameters import resolve_name
    from fitting.posterior import PosteriorWarning, sample_posterior

    load_before = os.getloadavg()[0]
    files, truth, data_s = benchmark_files(n_traces)
    truth = {resolve_name(p): value for p, value in zip(PARAMS, truth.tolist())}  # by label, as the results
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        began = time.perf_counter()
        plain = fitting.fit(files, PARAMS, covariance="noise", progress=False, throw=False)
        plain_s = time.perf_counter() - began
        youngs = fitting.fit(files, PARAMS, priors=[YOUNGS_PRIOR], covariance="noise", progress=False,
                             throw=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PosteriorWarning)
        cpu_began = time.process_time()
        posterior = sample_posterior(files, PARAMS, priors=[GAIN_PRIOR], chains=chains, warmup=warmup,
                                     draws=draws, seed=seed, progress=True)
        cpu_s = time.process_time() - cpu_began
    report = posterior.to_json()
    per_param = {}
    for label in posterior.labels:
        row = posterior.summary[label]
        entry = {"mean": row["mean"], "sd": row["sd"], "r_hat": row["r_hat"],
                 "ess_bulk": row["ess"], "ess_tail": row["ess_tail"],
                 "laplace_sd_ratio": posterior.laplace[label]["sd_ratio"]}
        if label in truth:
            entry["z_truth"] = (row["mean"] - truth[label]) / row["sd"]
            entry["noise_only_stderr"] = plain.stderr[label]
            entry["widening"] = row["sd"] / plain.stderr[label]
        per_param[label] = entry
    return {
        "case": f"{', '.join(PARAMS)} + sensor gains ({GAIN_PRIOR}) on {n_traces} traces of 21 beads "
                "(contacts 6, 11, wall; 2 ms at 1 us; noise 0.5 % of full scale)",
        "data_generation_s": data_s,
        "noise_only_fit_s": plain_s,
        "posterior": {
            "settings": posterior.settings,
            "timing_s": report["timing_s"],
            # CPU seconds of this process over the posterior (fit, warmup, sampling; all
            # threads): on a shared machine the wall time includes waiting for the cores,
            # this does not; over the cores' count, the least wall time quiet cores allow
            "cpu_s": cpu_s,
            "cpu_s_per_core": cpu_s / (os.cpu_count() or 1),
            "gradient_evaluations": report["gradient_evaluations"],
            "mean_tree_size": report["mean_tree_size"],
            "step_size": report["step_size"],
            "seconds_per_effective_sample": report["seconds_per_effective_sample"],
            "divergences": report["divergences"],
            "diagnostics_passed": report["diagnostics_passed"],
            "failed_diagnostics": report["failed_diagnostics"],
            "params": per_param,
            "target_10_min_met": report["timing_s"]["total"] <= 600.0,
            "target_5_min_met": report["timing_s"]["total"] <= 300.0,
            "target_3_min_met": report["timing_s"]["total"] <= 180.0,
        },
        "bead_youngs_prior": {
            "prior": YOUNGS_PRIOR,
            "stderr": {p: youngs.stderr[p] for p in PARAMS},
            "noise_only_stderr": {p: plain.stderr[p] for p in PARAMS},
            "widening": {p: youngs.stderr[p] / plain.stderr[p] for p in PARAMS},
            "relative_stderr_C": youngs.stderr["C"] / youngs.values["C"],
        },
        "truth": truth,
        "machine": {**machine_info(), "jax_devices": len(jax.devices()), "load_average_1min_before": load_before},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="posterior_bench.json", help="JSON output [posterior_bench.json]")
    parser.add_argument("--traces", type=int, default=10, help="number of traces [10]")
    parser.add_argument("--chains", type=int, default=4, help="chains [4]")
    parser.add_argument("--warmup", type=int, default=100, help="warmup iterations per chain [100]")
    parser.add_argument("--draws", type=int, default=200, help="draws per chain [200]")
    args = parser.parse_args(argv)
    from hertzchain.cli import expose_cpu_cores

    expose_cpu_cores()  # as `hertzchain fit --posterior`: the cores as devices
    from hertzchain.io.atomic import write_json

    result = benchmark_posterior(args.traces, chains=args.chains, warmup=args.warmup, draws=args.draws)
    write_json(args.out, result)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
