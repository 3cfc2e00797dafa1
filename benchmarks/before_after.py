"""Speed of two source trees of hertzchain, measured alternately in one run on one machine.

    python benchmarks/before_after.py --before DIR --after DIR --repeats 5 --out DIR
                                      [--sweep 21,1024,2500] [--traces 10] [--label TEXT]
                                      [--only conservative,damped_frictional,fit_iteration,fit]

The measurements of `benchmarks/run.py --quick` that both trees have, each run by the tree's
own worker (`TREE/benchmarks/run.py --worker`) in a process of its own with `PYTHONPATH=TREE`:

- `conservative`, `damped_frictional`: the standard sweep (`--sweep` N, B, steps: 21 beads,
  1024 chains, 2500 steps of 1 us; damped: eta = 2 us, mu = 0.19) through `solve_batched` as
  users call it (books off), the batch over the CPU's cores as host devices: bead-steps/s of
  the median of 11 runs (the `throughput` worker, which needs no Numba; the quick run's
  `pairs` worker times the same call beside Numba);
- `fit_iteration`: residuals and Jacobian in eta, mu, C of 10 synthetic traces of the paper's
  chain (median of 7), one conservative forward run of the same traces (median of 11), and
  their ratio;

and the whole `python -m hertzchain fit FILES --out DIR --quiet` as a user runs it, on
`--traces` files of the paper's chain written once by the after tree's `hertzchain synth`
(impact speeds 0.05-0.5 m/s log-spaced, contacts 6 and 11 and the wall, 2 ms at 1 us, eta =
2 us, mu = 0.19, mu* = 0.02, noise 0.5 % of each channel's full scale, seed 0; the paper case
of `benchmarks/fit_bench.py`), the wall time of the process:

- `fit_cold`: `HERTZCHAIN_CACHE` a fresh folder holding the tree's kernel libraries alone (as
  `hertzchain kernel` leaves them after installing) and no compiled JAX programs (JAX's
  persistent compilation cache lives in `$HERTZCHAIN_CACHE/jax`, `fitting/compilation_cache.py`);
- `fit_warm`: the same command again on that folder, the programs the cold run compiled read
  from the cache.

Each tree's kernel libraries are prepared once before the repeats: the libraries of the user's
cache (`$HERTZCHAIN_CACHE`, else `~/.cache/hertzchain`) are copied into `OUT/work/kernels/<tree>`
and the tree's `python -m hertzchain kernel` builds there what is missing (its time is stored,
and is in no measurement). A cold run during which a library had to be built is marked
(`built_libraries`).

Order: in each repeat every measurement runs before, then after (the fit: before's cold and
warm, then after's). Writes `OUT/latest.json` (every repeat; per measurement and tree the
median, min and max; the after/before ratio of the medians; whether the after median lies
within [min, max] of before's repeats or beyond them on the faster side), `OUT/latest.md` (the
table) and `OUT/latest.png` (every repeat over before's median), each written whole.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

TREES = ("before", "after")

# (key, description, unit, whether a larger value is faster)
MEASUREMENTS = (
    ("conservative.bead_steps_per_s", "conservative sweep", "bead-steps/s", True),
    ("damped_frictional.bead_steps_per_s", "damped + frictional sweep", "bead-steps/s", True),
    ("fit_iteration.iteration_s", "fit iteration (eta, mu, C; 10 traces)", "s", False),
    ("fit_iteration.forward_s", "conservative forward run (10 traces)", "s", False),
    ("fit_iteration.iteration_over_forward", "fit iteration / forward run", "ratio", False),
    ("fit_cold.wall_s", "hertzchain fit, cold", "s", False),
    ("fit_warm.wall_s", "hertzchain fit, warm", "s", False),
)

# The paper case of `benchmarks/fit_bench.py`, written by `hertzchain synth`.
SYNTH_VELOCITIES_M_S = (0.05, 0.5)  # log-spaced, one file each
SYNTH_OPTIONS = ("--contacts", "6,11", "--eta", "2us", "--mu", "0.19", "--mu-star", "0.02", "--t-end", "2ms",
                 "--sample-interval", "1us", "--noise-fraction", "0.005", "--seed", "0")


def summarise(before: list[float], after: list[float], larger_is_faster: bool) -> dict:
    """Median, min and max of each tree's repeats, the ratio after/before of the medians, and
    whether the after median lies within [min, max] of before's repeats (`within_before_range`)
    or beyond them on the faster side (`faster`); `same_or_faster` is either."""
    b_med, a_med = statistics.median(before), statistics.median(after)
    low, high = min(before), max(before)
    faster = a_med > high if larger_is_faster else a_med < low
    within = low <= a_med <= high
    return {"before": {"median": b_med, "min": low, "max": high},
            "after": {"median": a_med, "min": min(after), "max": max(after)},
            "ratio_after_over_before": a_med / b_med, "within_before_range": within, "faster": faster,
            "same_or_faster": within or faster}


def _user_cache() -> Path:
    """The kernel cache a user's commands read: `$HERTZCHAIN_CACHE`, else
    `$XDG_CACHE_HOME/hertzchain` (default `~/.cache/hertzchain`)."""
    from hertzchain.native import cache_dir

    return cache_dir()


def _libraries(folder: Path) -> set[str]:
    return {p.name for p in folder.glob("*.so")}


def _copy_libraries(source: Path, target: Path) -> None:
    """The kernel libraries of `source` and their build records where they have them (trees
    that check them) into `target`; no locks, no compiled JAX programs."""
    target.mkdir(parents=True, exist_ok=True)
    for library in source.glob("*.so"):
        shutil.copy2(library, target / library.name)
        record = library.with_name(library.name + ".json")
        if record.exists():
            shutil.copy2(record, target / record.name)


def _env(tree: Path, cache: Path, host_devices: int | None = None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), HERTZCHAIN_CACHE=str(cache))
    env.pop("HERTZCHAIN_NO_COMPILE_CACHE", None)
    env.setdefault("JAX_PLATFORMS", "cpu")
    if host_devices is not None:
        env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") +
                            f" --xla_force_host_platform_device_count={host_devices}").strip()
    return env


def _commit(tree: Path) -> dict:
    def git(*args):
        return subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True,
                              check=False).stdout.strip()

    return {"path": str(tree), "commit": git("rev-parse", "HEAD"), "subject": git("log", "-1", "--format=%s"),
            "uncommitted_changes": bool(git("status", "--porcelain", "--untracked-files=no"))}


def prepare_kernels(tree: Path, folder: Path) -> dict:
    """`folder` holding the tree's kernel libraries: the user's cache copied, then the tree's
    `hertzchain kernel` (which builds what is missing). Its wall time (s) and what it built."""
    _copy_libraries(_user_cache(), folder)
    had = _libraries(folder)
    began = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "hertzchain", "kernel", "--quiet"], cwd=tree,
                          env=_env(tree, folder), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{tree}: hertzchain kernel failed: {(done.stderr or done.stdout)[-1500:]}")
    return {"kernel_command_s": time.perf_counter() - began, "built": sorted(_libraries(folder) - had)}


def run_worker(tree: Path, cache: Path, kind: str, host_devices: int, **kwargs) -> dict:
    """The tree's own `benchmarks/run.py --worker` measurement `kind`, in a process of its own."""
    payload = json.dumps({"kind": kind, "kwargs": kwargs})
    done = subprocess.run([sys.executable, str(tree / "benchmarks" / "run.py"), "--worker", payload], cwd=tree,
                          env=_env(tree, cache, host_devices), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        return {"available": False, "reason": (done.stderr or done.stdout)[-1500:]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def _sweep_values(result: dict) -> dict:
    return {"bead_steps_per_s": result["bead_steps_per_s"]}


def _iteration_values(result: dict) -> dict:
    return {"iteration_s": result["iteration_s"], "forward_s": result["conservative_forward_s"],
            "iteration_over_forward": result["iteration_over_forward"]}


def run_fit(tree: Path, files: list[Path], out: Path, cache: Path) -> dict:
    """One `python -m hertzchain fit FILES --out OUT --quiet` of the tree on `cache`: the
    process's wall time (s), the fit's iterations and result, the libraries it built."""
    had = _libraries(cache)
    began = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "hertzchain", "fit", *map(str, files), "--out", str(out),
                           "--quiet"], cwd=tree, env=_env(tree, cache), capture_output=True, text=True, check=False)
    wall = time.perf_counter() - began
    if done.returncode != 0:
        return {"available": False, "reason": (done.stderr or done.stdout)[-1500:]}
    report = json.loads((out / "fit.json").read_text())
    return {"available": True, "wall_s": wall, "iterations": report["n_steps"], "converged": report["converged"],
            "reduced_chi2": report["reduced_chi2"],
            "values": {name: p["value"] for name, p in report["params"].items()},
            "built_libraries": sorted(_libraries(cache) - had)}


def write_data(tree: Path, folder: Path, n_traces: int, cache: Path) -> list[Path]:
    """The fit's trace files, written once by the tree's `hertzchain synth` (module docstring)."""
    import numpy as np

    velocities = ",".join(f"{v:.6g}" for v in np.geomspace(*SYNTH_VELOCITIES_M_S, n_traces))
    done = subprocess.run([sys.executable, "-m", "hertzchain", "synth", "--velocities", velocities,
                           *SYNTH_OPTIONS, "--out", str(folder)], cwd=tree, env=_env(tree, cache),
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"hertzchain synth failed: {(done.stderr or done.stdout)[-1500:]}")
    files = sorted(folder.glob("*.csv"))
    if len(files) != n_traces:
        raise RuntimeError(f"hertzchain synth wrote {len(files)} trace files into {folder}, not {n_traces}")
    return files


# The groups of measurements `--only` chooses from, each run by one worker or command.
PARTS = ("conservative", "damped_frictional", "fit_iteration", "fit")


def measure(trees: dict, repeats: int, out: Path, *, sweep: tuple[int, int, int], n_traces: int,
            parts: tuple[str, ...] = PARTS, log=print) -> dict:
    """The measurements of `parts` (`PARTS`) `repeats` times each, the trees alternately; the
    JSON-ready result."""
    cores = os.cpu_count() or 1
    work = out / "work"
    if work.exists():
        shutil.rmtree(work)
    kernels = {name: work / "kernels" / name for name in TREES}
    prepared = {}
    for name in TREES:
        log(f"{name}: preparing the kernel libraries")
        prepared[name] = prepare_kernels(trees[name], kernels[name])
    files = write_data(trees["after"], work / "data", n_traces, kernels["after"]) if "fit" in parts else []
    values = {name: {key: [] for key, *_ in MEASUREMENTS} for name in TREES}
    records = {name: [] for name in TREES}
    failures = []

    def keep(name, repeat, part, result, extract):
        record = {"repeat": repeat, "measurement": part, "finished_at_s": time.time(), **result}
        records[name].append(record)
        if not result.get("available", True):
            failures.append({"tree": name, "repeat": repeat, "measurement": part, "reason": result.get("reason")})
            return
        for field, value in extract(result).items():
            if f"{part}.{field}" in values[name]:
                values[name][f"{part}.{field}"].append(value)

    for repeat in range(repeats):
        for part, damped in (("conservative", False), ("damped_frictional", True)):
            for name in TREES if part in parts else ():
                log(f"repeat {repeat + 1}/{repeats}: {part}, {name}")
                n_beads, batch, steps = sweep
                result = run_worker(trees[name], kernels[name], "throughput", cores, impl="hertzchain",
                                    n_beads=n_beads, batch=batch, steps=steps, devices=cores, damped=damped)
                keep(name, repeat, part, result, _sweep_values)
        for name in TREES if "fit_iteration" in parts else ():
            log(f"repeat {repeat + 1}/{repeats}: fit_iteration, {name}")
            keep(name, repeat, "fit_iteration", run_worker(trees[name], kernels[name], "fit_iteration", 1),
                 _iteration_values)
        for name in TREES if "fit" in parts else ():
            cache = work / "fit_cache" / f"{name}{repeat}"
            _copy_libraries(kernels[name], cache)
            for part in ("fit_cold", "fit_warm"):
                log(f"repeat {repeat + 1}/{repeats}: {part}, {name}")
                result = run_fit(trees[name], files, work / "fit_out" / f"{name}{repeat}_{part}", cache)
                keep(name, repeat, part, result, lambda r: {"wall_s": r["wall_s"]})
            shutil.rmtree(cache)
    summary = {key: summarise(values["before"][key], values["after"][key], larger)
               for key, _, _, larger in MEASUREMENTS if values["before"][key] and values["after"][key]}
    return {"trees": {name: _commit(trees[name]) for name in TREES}, "kernel_libraries": prepared,
            "data": {"files": len(files), "written_by": "after", "synth_options": list(SYNTH_OPTIONS),
                     "velocities_m_s": f"{n_traces} log-spaced over {SYNTH_VELOCITIES_M_S}"},
            "settings": {"repeats": repeats, "sweep_n_beads_batch_steps": list(sweep), "host_devices": cores,
                         "parts": list(parts)},
            "values": values, "summary": summary, "runs": records, "failures": failures}


def markdown_table(result: dict) -> str:
    """The summary as a Markdown table: before's and after's median [min, max], the ratio of
    the medians, and the verdict."""
    trees = result["trees"]
    machine = result["machine"]
    lines = [(f"before_after: {result['label'] or 'unlabelled run'}; {result['settings']['repeats']} repeats, "
              f"{machine['cpus']} cores, load average {machine['load_average_before']} before, "
              f"{machine['load_average_after']} after; {result['wall_s']:.0f} s in all."),
             (f"before: {trees['before']['commit'][:10]} ({trees['before']['subject']}); "
              f"after: {trees['after']['commit'][:10]} ({trees['after']['subject']})."), "",
             "| measurement | unit | before median [min, max] | after median [min, max] | after / before | verdict |",
             "|---|---|---|---|---|---|"]
    for key, description, unit, _ in MEASUREMENTS:
        if key not in result["summary"]:
            lines.append(f"| {description} | {unit} | not measured | | | |")
            continue
        s = result["summary"][key]
        cells = [f"{s[t]['median']:.4g} [{s[t]['min']:.4g}, {s[t]['max']:.4g}]" for t in TREES]
        verdict = "faster" if s["faster"] else "same (within before's range)" if s["within_before_range"] else "SLOWER"
        lines.append(f"| {description} | {unit} | {cells[0]} | {cells[1]} | {s['ratio_after_over_before']:.3f} | "
                     f"{verdict} |")
    for failure in result["failures"]:
        lines.append(f"\nFailed: {failure['tree']}, repeat {failure['repeat'] + 1}, {failure['measurement']}: "
                     f"{(failure['reason'] or '').strip().splitlines()[-1:]}")
    return "\n".join(lines) + "\n"


def plot(result: dict, path: Path) -> None:
    """Every repeat of each measurement over before's median, before and after side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hertzchain.io.atomic import finish_figure

    keys = [(key, description) for key, description, *_ in MEASUREMENTS if key in result["summary"]]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    for offset, name, marker in ((-0.15, "before", "o"), (0.15, "after", "s")):
        for k, (key, _) in enumerate(keys):
            scale = result["summary"][key]["before"]["median"]
            points = [v / scale for v in result["values"][name][key]]
            ax.plot([k + offset] * len(points), points, marker, color="C0" if name == "before" else "C1",
                    alpha=0.7, label=name if k == 0 else None)
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_xticks(range(len(keys)), [d for _, d in keys], rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("repeat / before's median")
    ax.set_title("before / after, alternating runs (throughput: higher is faster; times, ratios: lower)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend()
    finish_figure(fig, path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, help="source tree measured first in each repeat")
    parser.add_argument("--after", required=True, help="source tree measured second in each repeat")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of every measurement per tree [5]")
    parser.add_argument("--out", required=True, help="output folder (latest.json, .md, .png; scratch in work/)")
    parser.add_argument("--sweep", default="21,1024,2500", help="N beads, B chains, steps of the sweeps [21,1024,2500]")
    parser.add_argument("--traces", type=int, default=10, help="trace files of the fit [10]")
    parser.add_argument("--label", default="", help="what the machine was doing (e.g. 'quiet', 'loaded')")
    parser.add_argument("--keep-work", action="store_true", help="keep OUT/work (kernels, data, fit outputs)")
    parser.add_argument("--only", default=",".join(PARTS),
                        help=f"comma-separated measurements to run, of {', '.join(PARTS)} [all]")
    args = parser.parse_args(argv)
    parts = tuple(part.strip() for part in args.only.split(",") if part.strip())
    unknown = [part for part in parts if part not in PARTS]
    if unknown or not parts:
        parser.error(f"--only {args.only!r}: choose from {', '.join(PARTS)}")
    trees = {"before": Path(args.before).resolve(), "after": Path(args.after).resolve()}
    for name, tree in trees.items():
        if not (tree / "hertzchain" / "__init__.py").exists() or not (tree / "benchmarks" / "run.py").exists():
            parser.error(f"--{name} {tree}: not a hertzchain source tree (no hertzchain/ or benchmarks/run.py)")
    for option in ("repeats", "traces"):
        if getattr(args, option) < 1:
            parser.error(f"--{option} must be at least 1")
    try:
        sweep = tuple(int(part) for part in args.sweep.split(","))
    except ValueError:
        sweep = ()
    if len(sweep) != 3 or min(sweep) < 1:
        parser.error(f"--sweep {args.sweep!r}: write three positive integers N,B,STEPS (e.g. 21,1024,2500)")
    from hertzchain.io.atomic import write_json, write_text

    out = Path(args.out)
    began = time.perf_counter()
    load_before = " ".join(f"{x:.2f}" for x in os.getloadavg())
    result = measure(trees, args.repeats, out, sweep=sweep, n_traces=args.traces, parts=parts,
                     log=lambda text: print(text, file=sys.stderr, flush=True))
    result = {"label": args.label,
              "machine": {"cpus": os.cpu_count(), "load_average_before": load_before,
                          "load_average_after": " ".join(f"{x:.2f}" for x in os.getloadavg())},
              "wall_s": time.perf_counter() - began, **result}
    if not args.keep_work:
        shutil.rmtree(out / "work")
    write_json(out / "latest.json", result)
    write_text(out / "latest.md", markdown_table(result))
    if result["summary"]:
        plot(result, out / "latest.png")
    print(markdown_table(result))
    return 1 if result["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
