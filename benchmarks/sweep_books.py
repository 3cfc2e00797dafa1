"""Damped and frictional sweeps with the books, on the fused C++ kernel and the JAX kernel.

A sweep (`hertzchain sweep`, `solve_batched` with its default `books=True`) reads every
contact's largest force and the energy books (dissipated, final kinetic and potential
energy) besides the recorded forces. Measured here:

1. the standard damped + frictional case of `run.py` (N = 21, B = 1024, 2500 steps of
   1 us, eta = 2 us, mu = 0.19) with the books: the default call (the full C++ kernel with
   the books, `native.run_full_books`), the JAX kernel (`kernel="jax"`) and, for scale, the
   default call without the books, interleaved in one process (medians of `--repeats`
   runs after a first, compiling one), and how far the two kernels' books are apart;
2. the whole `hertzchain sweep` command of a damped, frictional chain as a user runs it,
   in a fresh process, with the C++ kernel (already built: its build is timed apart) and
   with `HERTZCHAIN_NATIVE=0` (the JAX kernel), and with `--before DIR` the same command
   run from another checkout (e.g. `git worktree add DIR <commit>`; its kernel built first,
   untimed).

    python benchmarks/sweep_books.py --out benchmarks/results/sweep_books [--before DIR]

`--build-times` instead times the builds of the main C++ library and of the dashpot's, the
compliant sensors' and two laws' libraries from this checkout's source and from `--before`'s
(`build_times.json`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SWEEP_GRID = ("striker_velocity_m_s=0.1:1.0:64:log", "wall_youngs_pa=3e9:4e11:32:log")
SWEEP_PHYSICS = ("--eta", "2e-6", "--mu", "0.19", "--t-end", "2.5e-3", "--contacts", "9,10")


def in_process(repeats: int) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    sys.path.insert(0, str(HERE))
    from run_workers import DAMPED_ETA_S, DAMPED_MU, _case

    import hertzchain as hc
    from hertzchain import native
    from hertzchain.batched import kernel_flags, kernel_rows, solve_batched

    setup, grid, _, rows = _case(21, 1024, 2500, DAMPED_ETA_S, DAMPED_MU)
    recording = hc.Recording(rows)
    calls = {
        "fused_books": lambda: solve_batched(setup, grid, recording),
        "jax_books": lambda: solve_batched(setup, grid, recording, kernel="jax"),
        "fused_no_books": lambda: solve_batched(setup, grid, recording, books=False),
    }
    outs, times = {}, {name: [] for name in calls}
    for name, call in calls.items():  # the first run of each compiles
        outs[name] = jax.block_until_ready(call())
    for _ in range(repeats):
        for name, call in calls.items():
            start = time.perf_counter()
            jax.block_until_ready(call())
            times[name].append(time.perf_counter() - start)
    bead_steps = 21 * 1024 * grid.n_steps
    medians = {name: statistics.median(t) for name, t in times.items()}
    ours, reference = outs["fused_books"], outs["jax_books"]
    energy = np.asarray(reference.initial_energy_j)
    books_apart = {name: float(np.max(np.abs(np.asarray(getattr(ours, name)) - np.asarray(getattr(reference, name))))
                               / energy.max())
                   for name in ("dissipated_j", "kinetic_j", "potential_j", "energy_error_j")}
    return {
        "case": "N = 21, B = 1024, 2500 steps of 1 us, eta = 2 us, mu = 0.19, books on",
        "kernel": str(native.kernel_for(kernel_flags(setup), None, kernel_rows(setup))),
        "repeats": repeats,
        "run_s": medians,
        "runs_s": times,
        "throughput_bead_steps_per_s": {name: bead_steps / t for name, t in medians.items()},
        "speedup_fused_over_jax_with_books": medians["jax_books"] / medians["fused_books"],
        "books_cost_ratio_fused": medians["fused_books"] / medians["fused_no_books"],
        "books_difference_over_impact_energy": books_apart,
        "max_force_relative_difference": float(np.max(np.abs(np.asarray(ours.max_force_n)
                                                             - np.asarray(reference.max_force_n))
                                                      / np.asarray(reference.max_force_n))),
    }


def whole_command(native_on: bool, source: Path | None = None) -> dict:
    """`hertzchain sweep` of a damped, frictional 21-bead chain over 64 x 32 setups, in a
    fresh process (the package from `source` when given): its wall time and the table it wrote."""
    env = dict(os.environ, HERTZCHAIN_NATIVE="1" if native_on else "0")
    with tempfile.TemporaryDirectory() as scratch:
        # run from the scratch folder: `python -m` puts the working folder first on the path
        if source is not None:
            env["PYTHONPATH"] = str(source)
            subprocess.run([sys.executable, "-m", "hertzchain", "kernel"], env=env, check=True, capture_output=True,
                           cwd=scratch)
        out = Path(scratch) / "sweep"
        command = [sys.executable, "-m", "hertzchain", "sweep", "--n-beads", "21", *SWEEP_PHYSICS,
                   *(arg for g in SWEEP_GRID for arg in ("--grid", g)), "--out", str(out), "--no-plots"]
        start = time.perf_counter()
        proc = subprocess.run(command, capture_output=True, text=True, env=env, check=False, cwd=scratch)
        wall = time.perf_counter() - start
        if proc.returncode != 0:
            raise RuntimeError(proc.stderr[-3000:])
        import numpy as np
        import pyarrow.parquet as pq

        table = pq.read_table(out / "sweep.parquet")
        dissipated = table.column("dissipated_fraction").to_numpy()
        located = subprocess.run([sys.executable, "-c", "import hertzchain; print(hertzchain.__file__)"], env=env,
                                 cwd=scratch, capture_output=True, text=True, check=True).stdout.strip()
        return {"command": " ".join(command[1:]), "package": located, "wall_s": wall,
                "runs": table.num_rows,
                "dissipated_fraction_median": float(np.median(dissipated)),
                "stderr_tail": proc.stderr[-600:]}


def build_times(before: Path | None) -> dict:
    """Seconds to build the main C++ library, and the dashpot's, the compliant sensors' and two
    laws' libraries (built on first use), from this checkout's source (and from `before`'s), each into a scratch
    folder, one after the other."""
    env = dict(os.environ)
    prefix = "import sys, time, tempfile, pathlib; from hertzchain import native; t = time.perf_counter(); "
    scripts = {"main_library_build_s": prefix + "native._build(pathlib.Path(tempfile.mkdtemp()) / 'k.so')",
               "dashpot_library_build_s": prefix + "native._load_named('dashpot')",
               "sensor_library_build_s": prefix + "native._load_named('compliant sensors')",
               "jackson_green_library_build_s": prefix + "native._load_named('jackson_green')",
               "power_law_library_build_s": prefix + "native._load_named('power_law')"}
    times = {name: {} for name in scripts}
    for label, source in (("this_checkout", HERE.parent), ("before", before)):
        if source is None:
            continue
        for name, script in scripts.items():
            with tempfile.TemporaryDirectory() as scratch:
                env["PYTHONPATH"] = str(source)
                env["HERTZCHAIN_CACHE"] = scratch  # nothing built yet
                out = subprocess.run([sys.executable, "-c", script + "; print(time.perf_counter() - t)"], env=env,
                                     cwd=scratch, capture_output=True, text=True, check=True).stdout
                times[name][label] = float(out.strip().splitlines()[-1])
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--before", type=Path, help="another checkout whose sweep command is timed too")
    parser.add_argument("--build-times", action="store_true",
                        help="only time the libraries' builds (this checkout, and --before's), into build_times.json")
    args = parser.parse_args()
    if args.build_times:
        args.out.mkdir(parents=True, exist_ok=True)
        result = build_times(args.before.resolve() if args.before else None)
        result["machine"] = {"cores": len(os.sched_getaffinity(0)), "load_before": os.getloadavg()}
        partial = args.out / "build_times.json.partial"
        partial.write_text(json.dumps(result, indent=2))
        os.replace(partial, args.out / "build_times.json")
        print(result)
        return
    from hertzchain import native

    start = time.perf_counter()
    reason = native.unavailable_reason()  # builds the kernel once, outside every timing
    build_s = time.perf_counter() - start
    result = {
        "machine": {"cpu": platform.processor() or platform.machine(), "cores": len(os.sched_getaffinity(0)),
                    "load_before": os.getloadavg()},
        "native": reason or "available",
        "kernel_load_or_build_s": build_s,
        "in_process": in_process(args.repeats),
        "sweep_command": {"fused": whole_command(True), "jax": whole_command(False)},
    }
    result["machine"]["load_after"] = os.getloadavg()
    command = result["sweep_command"]
    command["speedup_fused_over_jax"] = command["jax"]["wall_s"] / command["fused"]["wall_s"]
    if args.before is not None:
        command["before"] = whole_command(True, args.before.resolve())
        command["speedup_over_before"] = command["before"]["wall_s"] / command["fused"]["wall_s"]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "sweep_books.json"
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps(result, indent=2))
    os.replace(partial, path)
    print(json.dumps({k: result["in_process"][k] for k in ("run_s", "speedup_fused_over_jax_with_books",
                                                           "books_cost_ratio_fused")}, indent=1))
    print("sweep command (s):", {k: v["wall_s"] for k, v in command.items() if isinstance(v, dict)})


if __name__ == "__main__":
    main()
