"""Benchmarks: hertzchain against NumPy, Numba and plain-JAX velocity-Verlet solvers, in one run.

    python benchmarks/run.py [--quick] [--avx2] [--gpu-sweep] --out DIR

`--avx2` builds the C++ kernel (`HERTZCHAIN_NATIVE_ARCH=haswell`) and compiles Numba for
AVX2 + FMA without AVX-512, to measure that code path on an AVX-512 machine.

`--quick` (under 3 minutes on 2 cores) measures the headline ratios alone: the standard
case conservative and damped + frictional (eta = 2 us, mu = 0.19), hertzchain against a
Numba kernel of the same physics, in alternating runs, and one fit iteration (residuals and
Jacobian of 10 traces in eta, mu, C) against one conservative forward run of the same
traces; with the machine's CPU flags. Without `--quick` it also sweeps N and B, the
gradient modes and a whole fit.

Every measurement runs in its own process (so peak memory and compile time are its own;
the hertzchain batch and the plain-JAX baseline run with the CPU's cores as host devices,
`--xla_force_host_platform_device_count`). Writes `DIR/latest.json`, `DIR/latest.csv` (one row
per implementation and size), `DIR/latest.png` (bead-steps/s against batch size) and
`DIR/latest.md` (the table); the stored runs are `benchmarks/results/run/full/` and, with
`--quick`, `benchmarks/results/run/quick/` (`--avx2`: `run/quick_avx2/`).

The case: the paper's chain (steel beads R = 13 mm, kappa = 1.2e10 N/m^1.5), N beads plus a
striker of the same steel, a Hertz wall; batches sweep the impact velocity over
0.1..1 m/s and the wall modulus over 3..400 GPa (log-spaced); dissipationless; dt = 1 us;
three forces recorded every step (contacts N//2 - 1, N//2 and the wall). Throughput is
bead-steps per second: N * B * steps / median wall time after compilation. `hertzchain` is
`solve_batched` as users call it (the fused C++ kernel where it is built), `hertzchain-jax`
the same call with `kernel="jax"` (the pure-JAX kernel), `hertzchain-books` the default
call with the maxima of every contact and the energy balance.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from run_workers import (  # the measurements, each run in its own process
    HERTZCHAIN_IMPLS,
    LABELS,
    QUICK_PAIRS,
    QUICK_REPEATS,
    SHARDED_IMPLS,
    SIZES_B,
    SIZES_N,
    STANDARD,
    STANDARD_PAIRS,
    STANDARD_STEPS,
    WORKERS,
    steps_for,
)

# --avx2: both codes built for Haswell's instruction set (AVX2, FMA; no AVX-512). Numba
# takes the host's features unless they are named.
AVX2_ENVIRONMENT = {
    "HERTZCHAIN_NATIVE_ARCH": "haswell",
    "NUMBA_CPU_NAME": "haswell",
    "NUMBA_CPU_FEATURES": "+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+cx16,+f16c,+fma,+lzcnt,+mmx,+movbe,+pclmul,"
                          "+popcnt,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,+xsave,-avx512f",
}



def _one_cpu() -> None:
    """Pin a worker (before it starts any thread) to the first CPU this process may use."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def _spawn(kind: str, host_devices: int = 1, env_extra=None, one_cpu: bool = False, **kwargs) -> dict:
    """Run worker `kind` in its own process with `host_devices` JAX CPU devices, on one CPU
    with `one_cpu` (Linux)."""
    if one_cpu and not hasattr(os, "sched_setaffinity"):
        return {"available": False, "reason": "no CPU affinity on this system"}
    env = dict(os.environ, **(env_extra or {}))
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={host_devices}"
    ).strip()
    env.setdefault("JAX_PLATFORMS", "cpu")
    payload = json.dumps({"kind": kind, "kwargs": kwargs})
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--worker", payload],
        capture_output=True, text=True, env=env, check=False, preexec_fn=_one_cpu if one_cpu else None,
    )
    if proc.returncode != 0:
        return {"available": False, "reason": (proc.stderr or proc.stdout)[-1500:]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------------------------------
# Report


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def _table(rows, machine) -> str:
    sizes = sorted({(r["n_beads"], r["batch"]) for r in rows if r.get("available")})
    header = "| implementation | " + " | ".join(f"N={n} B={b}" for n, b in sizes) + " |"
    lines = [header, "|" + "---|" * (len(sizes) + 1)]
    for impl in LABELS:
        cells = []
        for n, b in sizes:
            match = [r for r in rows if r.get("label") == impl and (r["n_beads"], r["batch"]) == (n, b)]
            cells.append(f"{match[0]['bead_steps_per_s']:.2g}" if match else "")
        if any(cells):
            lines.append(f"| {impl} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hertzchain.io.atomic import finish_figure

    fig, axes = plt.subplots(1, len({r["n_beads"] for r in rows}), figsize=(12, 4), squeeze=False)
    for ax, n in zip(axes[0], sorted({r["n_beads"] for r in rows})):
        for label, marker in (("hertzchain", "o"), ("hertzchain-books", "P"), ("hertzchain-jax", "X"),
                              ("hertzchain-1dev", "s"),
                              ("plain-jax", "D"), ("numba", "^"), ("numpy", "v")):
            pts = sorted((r["batch"], r["bead_steps_per_s"]) for r in rows if r["label"] == label and r["n_beads"] == n)
            if pts:
                ax.plot(*zip(*pts), marker=marker, label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("batch size B (chains)")
        ax.set_ylabel("throughput (bead-steps/s)")
        ax.set_title(f"N = {n} beads, f64, dt = 1 us")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    finish_figure(fig, path, dpi=120)


def _fit_iteration() -> dict:
    """`worker_fit_iteration` with the fused kernel and with the JAX kernel (in turn)."""
    out = {}
    for label, env in (("fused", {}), ("jax_kernel", {"HERTZCHAIN_NATIVE": "0"})):
        out[label] = _spawn("fit_iteration", host_devices=1, env_extra=env)
    return out


def quick(out: Path) -> dict:
    """The headline ratios in under 3 minutes on 2 quiet cores (see the module docstring)."""
    from hertzchain.io.atomic import write_json, write_text
    from hertzchain.progress import Progress

    cores = os.cpu_count() or 1
    start = time.perf_counter()
    load_before = _load()
    progress = Progress(7, "quick benchmark")
    machine = _spawn("machine")
    progress.advance()
    build = _spawn("build")  # the kernel's one-time compilation, not in any timing
    progress.advance()
    conservative = _spawn("pairs", host_devices=cores, damped=False, pairs=QUICK_PAIRS, repeats=QUICK_REPEATS)
    progress.advance()
    damped = _spawn("pairs", host_devices=cores, damped=True, pairs=QUICK_PAIRS, repeats=QUICK_REPEATS)
    progress.advance()
    # one core each (one thread each): the per-core ratio, which other jobs on the machine
    # bias less than the two codes' ways of sharing the cores
    one_core = {}
    for key, damped_case in (("conservative", False), ("damped_frictional", True)):
        one_core[key] = _spawn("pairs", one_cpu=True, damped=damped_case, pairs=QUICK_PAIRS, repeats=QUICK_REPEATS)
        progress.advance()
    fit = _spawn("fit_iteration")
    progress.advance()
    summary = {
        "mode": "quick",
        "machine": {**machine, "load_average_before": load_before, "load_average_after": _load()},
        "kernel_build": build,
        "conservative": conservative,
        "damped_frictional": damped,
        "one_core": one_core,
        "fit_iteration": fit,
        "wall_s": time.perf_counter() - start,
    }
    write_json(out / "latest.json", summary)
    write_text(out / "latest.md", _quick_table(summary) + "\n")
    return summary


def _quick_table(summary) -> str:
    machine = summary["machine"]
    lines = [f"Machine: {machine.get('cpu')}, {machine.get('cores')} cores, {machine.get('vector')}; "
             f"load average {machine.get('load_average_before')} before, {machine.get('load_average_after')} after.",
             f"Kernel built for -march={summary['conservative'].get('kernel_march', 'native')}, Numba for "
             f"{summary['conservative'].get('numba_cpu_name', 'host')}.",
             "", "| case | hertzchain bead-steps/s | Numba bead-steps/s | ratio (median) |", "|---|---|---|---|"]
    for key in ("conservative", "damped_frictional"):
        part = summary[key]
        if not part.get("available", True):
            lines.append(f"| {key} | unavailable: {part.get('reason', '')[-200:]} | | |")
            continue
        runs = part["runs"]
        numba = " / ".join(f"{r['numba']:.3g}" for r in runs)
        for label, field, ratio in (("host devices", "hertzchain", "hertzchain_over_numba"),
                                    ("one device", "hertzchain_one_device", "hertzchain_one_device_over_numba")):
            if field not in runs[0]:
                continue
            cells = " / ".join(f"{r[field]:.3g}" for r in runs)
            lines.append(f"| {key}, {label} | {cells} | {numba} | {part[ratio]:.2f} |")
    for key, part in summary.get("one_core", {}).items():
        if part.get("available", True):
            ours = " / ".join(f"{r['hertzchain']:.3g}" for r in part["runs"])
            numba = " / ".join(f"{r['numba']:.3g}" for r in part["runs"])
            lines.append(f"| {key}, one core | {ours} | {numba} | {part['hertzchain_over_numba']:.2f} |")
    fit = summary["fit_iteration"]
    if fit.get("available"):
        lines += ["", f"Fit iteration (residuals + Jacobian, {fit['n_traces']} traces, eta, mu, C): "
                  f"{fit['iteration_s'] * 1e3:.1f} ms = {fit['iteration_over_forward']:.2f}x one conservative "
                  f"forward run of the same traces ({fit['conservative_forward_s'] * 1e3:.1f} ms)."]
    lines.append(f"\nWall time of the quick run: {summary['wall_s']:.0f} s.")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="the headline ratios only (conservative, damped, fit iteration), < 3 min")
    parser.add_argument("--out", help="output folder")
    parser.add_argument("--gpu-sweep", action="store_true", help="also run benchmarks/gpu_sweep.py")
    parser.add_argument("--skip-fit", action="store_true", help="do not run the fit benchmark")
    parser.add_argument("--avx2", action="store_true",
                        help="build the C++ kernel and compile Numba for AVX2 + FMA (no AVX-512): the AVX2 "
                             "code path of both, measured on this machine")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        job = json.loads(args.worker)
        print(json.dumps(WORKERS[job["kind"]](**job["kwargs"])))
        return 0
    if not args.out:
        parser.error("--out DIR is required")
    if args.avx2:
        os.environ.update(AVX2_ENVIRONMENT)  # inherited by every worker
    if args.quick:
        summary = quick(Path(args.out))
        print(_quick_table(summary))
        return 0
    import numpy as np

    from hertzchain.io.atomic import write_json, write_text
    from hertzchain.progress import Progress

    out = Path(args.out)
    cores = os.cpu_count() or 1
    load_before = _load()
    sizes = [(n, b) for n in SIZES_N for b in SIZES_B]
    jobs = []
    for n, b in sizes:
        steps = STANDARD_STEPS if (n, b) == STANDARD else steps_for(n, b)
        for impl in HERTZCHAIN_IMPLS + ("numba", "plain-jax", "numpy"):
            devices = cores if impl in SHARDED_IMPLS else 1
            jobs.append(dict(impl=impl, n_beads=n, batch=b, steps=steps, devices=devices))
        if b > 1:
            jobs.append(dict(impl="hertzchain", n_beads=n, batch=b, steps=steps, devices=1))
    jobs.append(dict(impl="hertzchain-solve", n_beads=21, batch=1, steps=STANDARD_STEPS, devices=1))
    progress = Progress(len(jobs) + STANDARD_PAIRS + 4, "benchmarks")
    machine = _spawn("machine")
    progress.advance()
    rows = []
    for job in jobs:
        result = _spawn("throughput", host_devices=job["devices"], **job)
        if result.get("available"):
            label = job["impl"]
            if job["impl"] == "hertzchain" and job["devices"] == 1 and job["batch"] > 1:
                label = "hertzchain-1dev"
            result["label"] = label
            rows.append(result)
        else:
            print(f"{job}: {result.get('reason')}", file=sys.stderr)
        progress.advance()
    # The standard case's ratios again, in runs of hertzchain, then Numba, plain JAX and
    # hertzchain with books right after it: on a shared machine the load changes between
    # runs, and neighbouring runs share most of it.
    pairs, plain_pairs, books_pairs, jax_pairs = [], [], [], []
    for _ in range(STANDARD_PAIRS):
        n, b = STANDARD
        ours = _spawn("throughput", host_devices=cores, impl="hertzchain", n_beads=n, batch=b,
                      steps=STANDARD_STEPS, devices=cores)
        numba = _spawn("throughput", impl="numba", n_beads=n, batch=b, steps=STANDARD_STEPS, devices=1)
        plain = _spawn("throughput", host_devices=cores, impl="plain-jax", n_beads=n, batch=b,
                       steps=STANDARD_STEPS, devices=cores)
        books = _spawn("throughput", host_devices=cores, impl="hertzchain-books", n_beads=n, batch=b,
                       steps=STANDARD_STEPS, devices=cores)
        jax_kernel = _spawn("throughput", host_devices=cores, impl="hertzchain-jax", n_beads=n, batch=b,
                            steps=STANDARD_STEPS, devices=cores)
        if ours.get("available") and numba.get("available"):
            pairs.append((ours["bead_steps_per_s"], numba["bead_steps_per_s"]))
            if plain.get("available"):
                plain_pairs.append((ours["bead_steps_per_s"], numba["bead_steps_per_s"], plain["bead_steps_per_s"]))
            if books.get("available"):
                books_pairs.append((books["bead_steps_per_s"], numba["bead_steps_per_s"]))
            if jax_kernel.get("available"):
                jax_pairs.append((jax_kernel["bead_steps_per_s"], numba["bead_steps_per_s"]))
        progress.advance()
    gradient = _spawn("gradient")
    progress.advance()
    fit = {"available": False, "reason": "skipped (--skip-fit)"} if args.skip_fit else _spawn("fit")
    progress.advance()
    damped = _spawn("pairs", host_devices=cores, damped=True, pairs=STANDARD_PAIRS + 1, repeats=11)
    fit_iteration = _fit_iteration()
    progress.advance()

    def pick(label, n, b):
        match = [r for r in rows if r["label"] == label and (r["n_beads"], r["batch"]) == (n, b)]
        return match[0] if match else None

    standard = {label: pick(label, *STANDARD) for label in LABELS}
    bead_steps = {k: v["bead_steps_per_s"] for k, v in standard.items() if v and k != "hertzchain-1dev"}
    if {"hertzchain", "numba"} <= bead_steps.keys():
        pairs.insert(0, (bead_steps["hertzchain"], bead_steps["numba"]))
        if "plain-jax" in bead_steps:
            plain_pairs.insert(0, tuple(bead_steps[k] for k in ("hertzchain", "numba", "plain-jax")))
        if "hertzchain-books" in bead_steps:
            books_pairs.insert(0, (bead_steps["hertzchain-books"], bead_steps["numba"]))
        if "hertzchain-jax" in bead_steps:
            jax_pairs.insert(0, (bead_steps["hertzchain-jax"], bead_steps["numba"]))
    ratios = [ours / numba for ours, numba in pairs]
    books_ratios = [books / numba for books, numba in books_pairs]
    jax_ratios = [ours / numba for ours, numba in jax_pairs]
    over_plain = [ours / plain for ours, _, plain in plain_pairs]
    plain_over_numba = [plain / numba for _, numba, plain in plain_pairs]
    single = pick("hertzchain-books", 21, 1)
    single_forces_only = pick("hertzchain", 21, 1)
    solve_single = pick("hertzchain-solve", 21, 1)
    limit = machine.get("limit_bead_steps_per_s")
    grad = gradient.get("forward_mode_2.5ms", {}) if isinstance(gradient, dict) else {}
    reverse = gradient.get("checkpointed_2.5ms", {}) if isinstance(gradient, dict) else {}
    summary = {
        "machine": {**machine, "load_average_before": load_before, "load_average_after": _load()},
        "standard_case": "N=21, B=1024, dissipationless, dt=1us, 2500 steps, v0 0.1-1 m/s, "
        "Y_wall 3-400 GPa, 3 forces recorded every step (hertzchain-books: also the largest force "
        "of every contact at every step and the final energy balance)",
        "bead_steps_per_s": bead_steps,
        "hertzchain_over_numba": float(np.median(ratios)) if ratios else None,
        "hertzchain_over_numba_pairs": ratios,
        "hertzchain_over_numba_pairs_bead_steps_per_s": pairs,
        "hertzchain_books_over_numba": float(np.median(books_ratios)) if books_ratios else None,
        "hertzchain_books_over_numba_pairs": books_ratios,
        "hertzchain_jax_kernel_over_numba": float(np.median(jax_ratios)) if jax_ratios else None,
        "hertzchain_jax_kernel_over_numba_pairs": jax_ratios,
        "hertzchain_over_plain_jax": float(np.median(over_plain)) if over_plain else None,
        "hertzchain_over_plain_jax_runs": over_plain,
        "plain_jax_over_numba": float(np.median(plain_over_numba)) if plain_over_numba else None,
        "plain_jax_over_numba_runs": plain_over_numba,
        "triples_bead_steps_per_s": {"order": ["hertzchain", "numba", "plain-jax"], "runs": plain_pairs},
        "hertzchain_one_device_bead_steps_per_s": standard["hertzchain-1dev"]["bead_steps_per_s"]
        if standard["hertzchain-1dev"] else None,
        "fraction_of_machine_limit": {k: v / limit for k, v in bead_steps.items()} if limit else None,
        "paper_run_ms": {
            "solve_batched_B1": single["run_s"] * 1e3 if single else None,
            "solve_batched_B1_forces_only": single_forces_only["run_s"] * 1e3 if single_forces_only else None,
            "solve_batched_B1_jax_kernel": pick("hertzchain-jax", 21, 1)["run_s"] * 1e3
            if pick("hertzchain-jax", 21, 1) else None,
            "solve": solve_single["run_s"] * 1e3 if solve_single else None,
            "numba": pick("numba", 21, 1)["run_s"] * 1e3 if pick("numba", 21, 1) else None,
        },
        "compile_s": {
            "solve_batched_standard": standard["hertzchain-books"]["compile_s"] if standard["hertzchain-books"] else None,
            "solve_batched_B1": single["compile_s"] if single else None,
            "solve": solve_single["compile_s"] if solve_single else None,
        },
        "grad_over_forward": grad.get("grad_over_forward"),
        "grad_over_forward_method": "jax.jacfwd through solve, d/d eta, N = 21, 2500 steps",
        "grad_over_forward_reverse_mode": reverse.get("grad_over_forward"),
        "gradient": gradient,
        "fit": fit,
        "damped_frictional": damped,
        "fit_iteration": fit_iteration,
        "runs": rows,
    }
    write_json(out / "latest.json", summary)
    columns = ("label", "n_beads", "batch", "steps", "devices", "bead_steps_per_s", "run_s",
               "run_min_s", "run_max_s", "compile_s", "peak_rss_mb", "checksum_wall_max_n")
    write_text(out / "latest.csv", "\n".join(
        [",".join(columns)] + [",".join(str(r.get(c, "")) for c in columns) for r in rows]
    ) + "\n")
    write_text(out / "latest.md", _table(rows, machine) + "\n")
    _plot(rows, out / "latest.png")
    if args.gpu_sweep:
        subprocess.run([sys.executable, str(HERE / "gpu_sweep.py"), "--out", str(out / "gpu_sweep.json")], check=False)
    print(json.dumps({k: summary[k] for k in ("bead_steps_per_s", "hertzchain_over_numba", "hertzchain_over_numba_pairs",
                                              "hertzchain_books_over_numba", "hertzchain_jax_kernel_over_numba",
                                              "hertzchain_over_plain_jax", "plain_jax_over_numba", "paper_run_ms",
                                              "compile_s", "grad_over_forward")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
