"""One fit iteration against the number of traces: how the fused kernel's blocks of chains
share the cores.

    python benchmarks/fit_iteration_scaling.py --out FILE.json [--traces 1,4,5,8,10,16,20,24,40]

For each count n: n traces of `run.py`'s fit iteration (`run.fit_bench_traces`), and the
whitened residuals with their Jacobian in eta, mu, C (`fitting.model.residuals_and_jacobian`),
timed 7 times after a first call (median and least, ms). The host kernel splits the chains into blocks of 64, 8 and 4 lanes and single
chains (`chain_kernel.cc`), run side by side on the process's CPUs: the time steps where a
block more or less leaves a core idle.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from run_workers import _time, fit_bench_traces  # noqa: E402  (_time: first call s, median s, min s, max s, result)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="output JSON file")
    parser.add_argument("--traces", default="1,4,5,8,10,16,20,24,40", help="comma-separated trace counts")
    parser.add_argument("--label", default="", help="what this run is (e.g. the commit), stored with it")
    args = parser.parse_args(argv)
    counts = [int(c) for c in args.traces.split(",")]

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from fitting.fit import initial_values, make_problem
    from fitting.model import residuals_and_jacobian
    from hertzchain import native
    from hertzchain.io.atomic import write_json

    result = {"label": args.label, "cpus": len(os.sched_getaffinity(0)), "processor": platform.processor(),
              "kernel": native.unavailable_reason() or "host C++ kernel", "fit_iteration_ms": {}}
    for n in counts:
        files = fit_bench_traces(n)
        problem = make_problem(files, ("eta_s", "mu", "C"))
        x = jnp.asarray(initial_values(problem))
        first, median, low, _, _ = _time(lambda: residuals_and_jacobian(problem, x), 7)
        result["fit_iteration_ms"][str(n)] = {"median_ms": 1e3 * median, "min_ms": 1e3 * low}
        print(f"{n} traces: median {1e3 * median:.1f} ms, least {1e3 * low:.1f} ms", flush=True)
    result["load_average_1min_after"] = os.getloadavg()[0]
    write_json(Path(args.out), result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
