"""The fit's stopping rule on stick-slip losses from a second code path.

Track friction (Coulomb, mu = 0.19) hidden in records made by the diffrax reference solver
(`hertzchain.reference`: adaptive Dopri8, friction as its tanh regularisation), not by the
Verlet kernel the fit runs; three setups of `independent_data.SETUPS` (the paper's 21 steel
beads, 15 brass beads struck by a smaller brass ball, 12 glass beads struck by a steel ball),
three shots each (0.05, 0.5, 1.5 m/s; the paper's chain 0.05, 0.3, 1.0), two noise levels (0.5 %
and 2 % of each channel's peak), piezo channels, 11 bits, 2 us sampling.

Each case is fitted for `mu` and `C` as a user would (`fitting.fit`, default tolerance: n
steps), and fitted again with `max_steps` = n - `--within` - 1 (default `--within` 8; the same
deterministic path, cut short): the rule holds when that shorter fit's chi^2 is not yet within
the optimum's threshold of the full fit's (`OPTIMUM_TOLERANCE` x max(1, chi^2/dof)): chi^2
became final at step n - `--within` or later, so the fit stopped within `--within` iterations
of reaching it (a fit of at most `--within` + 1 steps holds by itself).

    python benchmarks/stopping_rule.py [--setups paper,brass,glass] [--noise 0.005,0.02] [--out DIR]

Writes `DIR/latest.json` (default `benchmarks/results/stopping_rule`): per case the steps,
chi^2 of both fits, the threshold, whether the rule held, mu fitted with its error, the time.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import fitting  # noqa: E402
from fitting.optimum import OPTIMUM_TOLERANCE  # noqa: E402
from hertzchain.io.atomic import json_ready, write_json  # noqa: E402
from independent_data import STRENGTHS, hidden_records  # noqa: E402

VELOCITIES_M_S = {"paper": (0.05, 0.3, 1.0), "brass": (0.05, 0.5, 1.5), "glass": (0.05, 0.5, 1.5)}
PARAMS = ("mu", "C")


def run_case(setup: str, noise_fraction: float, within: int, seed: int) -> dict:
    began = time.perf_counter()
    files = hidden_records(setup, ("track_friction",), code_path="diffrax", seed=seed,
                           noise_fraction=noise_fraction, velocities_m_s=VELOCITIES_M_S[setup])
    made = time.perf_counter()
    full = fitting.fit(files, PARAMS, progress=False, throw=False)
    fitted = time.perf_counter()
    threshold = OPTIMUM_TOLERANCE * max(1.0, full.reduced_chi2)
    entry = {"setup": setup, "noise_fraction": noise_fraction, "converged": bool(full.converged),
             "message": full.message, "n_steps": int(full.n_steps), "chi2": float(full.chi2),
             "reduced_chi2": float(full.reduced_chi2), "threshold": threshold,
             "mu": {"fitted": full.values["mu"], "stderr": full.stderr["mu"], "true": STRENGTHS["track_friction"]},
             "data_s": made - began, "fit_s": fitted - made}
    shorter_steps = full.n_steps - within - 1
    if shorter_steps < 1:
        entry.update(shorter_steps=0, chi2_shorter=None, holds=bool(full.converged))
    else:
        shorter = fitting.fit(files, PARAMS, max_steps=shorter_steps, progress=False, throw=False)
        entry.update(shorter_steps=int(shorter_steps), chi2_shorter=float(shorter.chi2),
                     holds=bool(full.converged and shorter.chi2 - full.chi2 >= threshold))
    entry["runtime_s"] = time.perf_counter() - began
    return entry


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--setups", default="paper,brass,glass")
    parser.add_argument("--noise", default="0.005,0.02", help="noise levels, fractions of each channel's peak")
    parser.add_argument("--within", type=int, default=8, help="iterations allowed after chi^2 is final [8]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results/stopping_rule"))
    args = parser.parse_args(argv)
    setups = [s.strip() for s in args.setups.split(",") if s.strip()]
    unknown = [s for s in setups if s not in VELOCITIES_M_S]
    if unknown:
        parser.error(f"--setups: unknown {', '.join(unknown)}; known: {', '.join(VELOCITIES_M_S)}")
    noises = [float(n) for n in args.noise.split(",") if n.strip()]
    results = {"code_path": "diffrax (hertzchain.reference), tanh-regularised Coulomb friction",
               "params": list(PARAMS), "within": args.within, "cpu_count": os.cpu_count(),
               "load_average_1min_at_start": os.getloadavg()[0], "cases": []}
    for setup in setups:
        for noise in noises:
            entry = run_case(setup, noise, args.within, args.seed)
            results["cases"].append(entry)
            print(f"{setup}, noise {100 * noise:g} %: {entry['n_steps']} steps, chi2/dof {entry['reduced_chi2']:.3f}, "
                  f"rule {'holds' if entry['holds'] else 'FAILS'} ({entry['runtime_s']:.0f} s)", flush=True)
    results["load_average_1min_at_end"] = os.getloadavg()[0]
    results["all_hold"] = all(e["holds"] for e in results["cases"])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "latest.json", json_ready(results))
    return 0 if results["all_hold"] else 1


if __name__ == "__main__":
    sys.exit(main())
