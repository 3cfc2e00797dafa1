"""Page faults and throughput of repeated `solve_batched` runs, with and without
`hertzchain.native`'s malloc tuning (`_keep_freed_buffers`).

    python benchmarks/allocation.py [--out DIR] [--runs 16]

The standard damped + frictional case of `benchmarks/run.py` (N = 21, B = 1024, 2500 steps
of 1 us, eta = 2 us, mu = 0.19, three forces every step: 61 MB of traces a run), run
`--runs` times in a fresh process for each setting (`HERTZCHAIN_MALLOC_TUNING` = 1, 0), and
the Numba baseline of `benchmarks/baselines.py` (the default allocator) likewise, twice each,
interleaved: each run's bead-steps/s and minor page faults (`getrusage`). Writes
`DIR/latest.json`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def worker(runs: int, impl: str) -> dict:
    import resource
    import time

    import jax

    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(HERE.parent))
    sys.path.insert(0, str(HERE))
    import run_workers as bench

    from hertzchain import native
    from hertzchain.batched import solve_batched
    from hertzchain.integrate import Recording

    setup, grid, arrays, rows = bench._case(21, 1024, bench.STANDARD_STEPS, eta_s=bench.DAMPED_ETA_S,
                                            mu=bench.DAMPED_MU)
    recording = Recording(tuple(rows))
    if impl == "numba":
        import baselines

        args = (arrays["mass_kg"], arrays["kappa"], arrays["wall_kappa"], arrays["v0"], bench.DT_S,
                bench.STANDARD_STEPS, rows)

        def one_run():
            baselines.numba_damped_batch(*args, eta_s=bench.DAMPED_ETA_S,
                                         friction_decel_m_s2=arrays["friction_decel_m_s2"])
    else:
        def one_run():
            jax.block_until_ready(solve_batched(setup, grid, recording, books=False).forces_n)
    bead_steps = 21 * 1024 * bench.STANDARD_STEPS
    throughput, faults = [], []
    for _ in range(runs + 1):  # the first run compiles
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        began = time.perf_counter()
        one_run()
        throughput.append(bead_steps / (time.perf_counter() - began))
        faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    ordered = sorted(throughput[1:])
    tuned = impl == "hertzchain" and native._load() is None and os.environ.get(native.MALLOC_VARIABLE, "1") != "0"
    return {"impl": impl, "tuned": tuned,
            "bead_steps_per_s": throughput[1:], "page_faults": faults[1:],
            "median_bead_steps_per_s": ordered[len(ordered) // 2],
            "median_page_faults": sorted(faults[1:])[len(faults[1:]) // 2]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="benchmarks/results/allocation", help="output folder [benchmarks/results/allocation]")
    parser.add_argument("--runs", type=int, default=16, help="timed runs per setting [16]")
    parser.add_argument("--worker", choices=("hertzchain", "numba"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.runs, args.worker)))
        return 0
    sys.path.insert(0, str(HERE))
    from fit_bench import machine_info

    results = {"case": "N=21, B=1024, 2500 steps of 1 us, eta 2 us, mu 0.19, 3 forces every step",
               "load_average_before": os.getloadavg(), "machine": machine_info()}
    for impl, setting in (("hertzchain", "1"), ("hertzchain", "0"), ("numba", "0")) * 2:
        env = {**os.environ, "HERTZCHAIN_MALLOC_TUNING": setting}
        done = subprocess.run([sys.executable, __file__, "--worker", impl, "--runs", str(args.runs)], env=env,
                              capture_output=True, text=True, check=True)
        row = json.loads(done.stdout.strip().splitlines()[-1])
        key = "numba" if impl == "numba" else ("tuned" if setting == "1" else "untuned")
        results.setdefault(key, []).append(row)
        print(f"{key}: median {row['median_bead_steps_per_s']:.3g} bead-steps/s, "
              f"median {row['median_page_faults']} page faults a run", flush=True)
    results["load_average_after"] = os.getloadavg()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(HERE.parent))
    from hertzchain.io.atomic import write_json

    write_json(out / "latest.json", results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
