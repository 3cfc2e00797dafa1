"""Benchmark of the whole `hertzchain fit` command, cold and warm, by phase, on two setups.

    python benchmarks/fit_bench.py [--out benchmarks/results/fit_bench/latest.json] [--traces 10]
                                   [--cases paper,brass] [--label TEXT]

writes the JSON and a Markdown table beside it (`--table-from JSON` rewrites the table alone).

Cases (10 trace files each, 0.5 % noise of each file's largest force, written as
hertzchain-trace CSV files and fitted for eta, mu, C from the data-derived start):

- `paper`: the paper's 21-bead steel chain, impact velocities log-spaced over 0.05-0.5 m/s,
  contacts 6 and 11 and the wall, 2 ms at 1 us; eta = 2 us, mu = 0.19, mu* = 0.02.
- `brass`: 15 brass beads (R = 5 mm), a 3 mm (radius) steel striker, velocities over 0.1-1 m/s,
  contacts 4 and 9 and the wall, 1 ms at 1 us; eta = 1 us, mu = 0.1, mu* = 0.02.

Each case runs the command (`python -m hertzchain fit FILES --out DIR --quiet`) three times,
each in a fresh process: first (`HERTZCHAIN_CACHE` pointed at an empty folder: the fused C++
kernel is built, once per machine, as `hertzchain kernel` does after installing, and every
program compiled), cold (the kernel built, no compiled JAX programs: the command as a user
first runs it after installing) and warm (the programs the cold run compiled, read from JAX's persistent compilation cache). Measured: the wall time of the whole process, and its phases
from the command's own `timings.json` and `fit.json`: start-up and imports (the rest of the
wall time), reading the files, the fit's set-up, compilation with the start's evaluation (until
the first iteration), the iterations, the final Jacobian and test of an optimum, covariance,
and writing the report. `benchmark_files()` (the paper case's traces) is shared with
`benchmarks/posterior_bench.py`.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from fitting.parameters import public_label

TRUTH = {"eta": 2e-6, "mu": 0.19, "mu_star": 0.02}
BRASS_TRUTH = {"eta": 1e-6, "mu": 0.1, "mu_star": 0.02}


def benchmark_files(n_traces: int = 10, *, t_end_s: float = 2e-3, noise_fraction: float = 0.005,
                    seed: int = 0):
    """The paper case's traces (see the module docstring): (files, truth of eta, mu, C (SI),
    seconds to simulate them)."""
    from fitting.synthetic import paper_setups

    velocities = np.geomspace(0.05, 0.5, n_traces)
    setups = paper_setups(velocities, eta_s=TRUTH["eta"], mu=TRUTH["mu"], mu_star=TRUTH["mu_star"])
    return _traces(setups, (6, 11), t_end_s, noise_fraction, seed, TRUTH["mu_star"])


def brass_files(n_traces: int = 10, *, t_end_s: float = 1e-3, noise_fraction: float = 0.005, seed: int = 0):
    """The brass case's traces (module docstring), as `benchmark_files`."""
    from hertzchain import ChainSetup
    from hertzchain.materials import BRASS

    setups = [ChainSetup(15, bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                         bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson, striker_radius_m=3e-3,
                         striker_density_kg_m3=7850.0, striker_youngs_pa=200e9, striker_poisson=0.29,
                         striker_velocity_m_s=float(v), eta_s=BRASS_TRUTH["eta"], mu=BRASS_TRUTH["mu"],
                         mu_star=BRASS_TRUTH["mu_star"])
              for v in np.geomspace(0.1, 1.0, n_traces)]
    return _traces(setups, (4, 9), t_end_s, noise_fraction, seed, BRASS_TRUTH["mu_star"])


def _traces(setups, contacts, t_end_s, noise_fraction, seed, mu_star):
    from fitting.parameters import bare_speed_constant
    from fitting.synthetic import synthetic_traces

    began = time.perf_counter()
    clean = synthetic_traces(setups, contacts=contacts, t_end_s=t_end_s)
    sigma = [noise_fraction * max(np.max(v) for v in f.channels.values()) for f in clean]
    files = synthetic_traces(setups, contacts=contacts, t_end_s=t_end_s, noise_std_n=sigma, seed=seed)
    truth = np.array([float(setups[0].eta_s), float(setups[0].mu),
                      float(bare_speed_constant(setups[0])) * (1 + mu_star) ** (1 / 3)])
    return files, truth, time.perf_counter() - began


CASES = {
    "paper": ("eta, mu, C on 10 traces of the paper's 21 steel beads (contacts 6, 11, wall; 2 ms at 1 us; "
              "noise 0.5 % of full scale)", benchmark_files),
    "brass": ("eta, mu, C on 10 traces of 15 brass beads, 3 mm steel striker (contacts 4, 9, wall; 1 ms at "
              "1 us; noise 0.5 % of full scale)", brass_files),
}


def run_command(paths, out: Path, cache: Path) -> dict:
    """One `hertzchain fit` process on `paths`; its wall time and phases (s)."""
    env = dict(os.environ, HERTZCHAIN_CACHE=str(cache), PYTHONPATH=str(ROOT))
    env.pop("HERTZCHAIN_NO_COMPILE_CACHE", None)
    began = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "hertzchain", "fit", *map(str, paths), "--out", str(out),
                           "--quiet"], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - began
    if done.returncode != 0:
        raise RuntimeError(f"hertzchain fit failed ({done.returncode}): {done.stderr[-2000:]}")
    timings = json.loads((out / "timings.json").read_text())
    report = json.loads((out / "fit.json").read_text())
    phases = {"start_up_and_imports_s": wall - timings["since_start_s"], "reading_s": timings["reading_s"],
              **{f"fit_{k}": v for k, v in report["timings_s"].items()}, "writing_s": timings["writing_s"]}
    return {"wall_s": wall, "phases_s": phases, "iterations": report["n_steps"], "converged": report["converged"],
            "reduced_chi2": report["reduced_chi2"],
            "values": {k: report["params"][public_label(k)]["value"] for k in ("eta", "mu", "C")},
            "stderr": {k: report["params"][public_label(k)]["stderr"] for k in ("eta", "mu", "C")}}


def benchmark_case(name: str, n_traces: int = 10) -> dict:
    """Cold and warm runs of the command on case `name`; a JSON-ready dict."""
    from hertzchain.io.tracefile import write_trace

    description, make = CASES[name]
    files, truth, data_s = make(n_traces)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        paths = []
        for k, trace in enumerate(files):
            paths.append(folder / f"shot{k}.csv")
            write_trace(paths[-1], trace)
        first = run_command(paths, folder / "first", folder / "first_cache")
        (folder / "cache").mkdir()
        for built in (folder / "first_cache").glob("*.so"):  # the kernel as installed, no JAX programs
            shutil.copy2(built, folder / "cache" / built.name)
        cold = run_command(paths, folder / "cold", folder / "cache")
        warm = run_command(paths, folder / "warm", folder / "cache")
    values = np.array([cold["values"][k] for k in ("eta", "mu", "C")])
    stderr = np.array([cold["stderr"][k] for k in ("eta", "mu", "C")])
    return {"case": description, "data_generation_s": data_s, "first": first, "cold": cold, "warm": warm,
            "truth": dict(zip(("eta", "mu", "C"), truth.tolist())),
            "z_scores": dict(zip(("eta", "mu", "C"), ((values - truth) / stderr).tolist()))}


PHASES = (("start_up_and_imports_s", "start-up, imports"), ("reading_s", "reading"), ("fit_set_up_s", "set-up"),
          ("fit_to_first_iteration_s", "to the first iteration (compilation)"), ("fit_iterations_s", "iterations"),
          ("fit_final_jacobian_and_test_s", "final Jacobian and test"), ("writing_s", "writing"))


def markdown_table(result: dict) -> str:
    """The result's wall times by phase as a Markdown table (s, one decimal)."""
    lines = [f"fit_bench: {result['label']} (load average {result['load_average_1min_before']:.1f} before, "
             f"{result['machine']['load_average_1min']:.1f} after; {result['machine']['cpus']} cores)", "",
             "| case | run | wall | " + " | ".join(name for _, name in PHASES) + " |",
             "|---|---|---|" + "---|" * len(PHASES)]
    for name, case in result["cases"].items():
        for run in ("first", "cold", "warm"):
            if run not in case:  # results stored before the first run was timed
                continue
            r = case[run]
            cells = [f"{r['phases_s'][key]:.1f}" for key, _ in PHASES]
            cells[4] += f" ({r['iterations']})"
            lines.append(f"| {name} | {run} | {r['wall_s']:.1f} s | " + " | ".join(cells) + " |")
    lines += ["", "z-scores of the cold fit against the truth: " + "; ".join(
        f"{name}: " + ", ".join(f"{k} {v:.3f}" for k, v in case["z_scores"].items())
        for name, case in result["cases"].items())]
    return "\n".join(lines) + "\n"


def machine_info() -> dict:
    """The cores, the processor and the 1-minute load average when a benchmark ends."""
    return {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
            "load_average_1min": os.getloadavg()[0]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "fit_bench" / "latest.json"),
                        help="JSON output [benchmarks/results/fit_bench/latest.json]")
    parser.add_argument("--traces", type=int, default=10, help="trace files per case [10]")
    parser.add_argument("--cases", default="paper,brass", help="cases to run [paper,brass]")
    parser.add_argument("--label", default="", help="what the machine was doing (e.g. 'quiet', 'loaded')")
    parser.add_argument("--table-from", metavar="JSON",
                        help="only write the Markdown table (beside the JSON) of a stored result")
    args = parser.parse_args(argv)
    from hertzchain.io.atomic import write_json, write_text

    if args.table_from:
        path = Path(args.table_from)
        write_text(path.with_suffix(".md"), markdown_table(json.loads(path.read_text())))
        return 0

    load_before = os.getloadavg()[0]
    result = {"label": args.label, "load_average_1min_before": load_before,
              "cases": {name: benchmark_case(name, args.traces) for name in args.cases.split(",")},
              "machine": machine_info()}
    write_json(args.out, result)
    write_text(Path(args.out).with_suffix(".md"), markdown_table(result))
    print(markdown_table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
