"""Confusion table of the diagnosis: which effect was hidden vs which effects were named.

For every candidate effect (and for "none" and a few pairs), synthetic trace files are made
with that effect hidden (`fitting.hidden.hidden_effect_traces`, nominal strengths, noise
and nuisances drawn per seed), the diagnosis runs from the base model, and the named
effects are tallied. Writes `latest.csv`, `latest.json` and `latest.md` (with the
run time of every diagnosis) into `--out`; `confusion_quick.*` with --quick, and
`confusion_independent_<code path>.*` with --independent.

    python benchmarks/confusion.py --quick            # 8-bead chain, one seed per row
    python benchmarks/confusion.py --seeds 3 --pairs  # the paper's 21-bead chain, pairs too
    python benchmarks/confusion.py --independent      # data from elsewhere (independent_data.py):
                                                      # paper and brass setups, diffrax, piezo, 11 bits
    python benchmarks/confusion.py --independent --code-path verlet  # the same from the Verlet solver
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax
from independent_data import SETUPS, hidden_records, true_strength

import hertzchain as hc
from fitting.diagnosis import diagnose
from fitting.effects import EFFECT_NAMES, nominal_yield_forces_n
from fitting.hidden import hidden_effect_traces
from hertzchain.io.atomic import write_csv, write_json, write_text

PAIRS = (("viscous_damping", "wall_compliance"), ("track_friction", "sensor_dynamics"),
         ("viscous_damping", "track_friction"))


def recovered(setup: str, effect: str, values: dict) -> float | None:
    """The strength of a named `effect` as `independent_data.true_strength` states it (yield
    force in N, exponent n, preload in N, beta, SI values), from the diagnosis's fitted
    `values`; None for an effect stated otherwise (wall softening, bead radii)."""
    if effect == "plasticity":  # the softening scales the nominal yield force by its cube
        spec = SETUPS[setup]
        nominal = float(nominal_yield_forces_n(hc.ChainSetup(spec["n_beads"], **spec["fields"]))[1])
        return nominal / values["yield_softening"] ** 3
    if effect == "contact_exponent":
        return 1.5 + values["exponent_shift"]
    direct = {"viscous_damping": "eta_s", "dashpot_damping": "dashpot_n_s_m", "track_friction": "mu",
              "rotational_friction": "mu_star", "precompression": "preload_n", "sensor_dynamics": "sensor_beta"}
    return values[direct[effect]] if effect in direct else None


def run_case(hidden, seed, *, n_beads=None, noise_fraction=None, contacts=None, velocities=None, setup=None,
             code_path=None):
    """One diagnosis of data with `hidden` effects: from `fitting.hidden` or, with `setup`,
    from `independent_data.hidden_records(setup, hidden, code_path=...)`."""
    if setup is None:
        files = hidden_effect_traces(hidden, n_beads=n_beads, contacts=contacts, velocities_m_s=velocities,
                                     noise_fraction=noise_fraction, seed=seed)
    else:
        files = hidden_records(setup, hidden, code_path=code_path, seed=seed)
    began, cpu = time.perf_counter(), time.process_time()
    result = diagnose(files, progress=False)
    cpu = time.process_time() - cpu
    jax.clear_caches()  # each diagnosis compiles its own models: free them before the next
    return {
        "hidden": list(hidden),
        "setup": setup or f"{n_beads} beads (fitting.hidden)",
        "code_path": code_path or "verlet",
        "seed": seed,
        "named": list(result.missing_effects),
        "correct": sorted(result.missing_effects) == sorted(hidden),
        "alarm": result.misspecification,
        "gap_base": result.base_fit["gap"],
        "gap_final": result.final["gap"],
        "not_separable": result.not_separable,
        # the candidates refitted in each round (the screen's choice), first round first
        "refitted": [[c.effect for c in candidates if c.separable and c.chi2 == c.chi2]
                     for candidates in [s.candidates for s in result.steps] + [result.last_candidates]],
        "runtime_s": time.perf_counter() - began,
        "cpu_s": cpu,  # the process's CPU time (every thread's): what a load on the machine leaves as it was
        "loadavg": list(os.getloadavg()),
    } | ({"strengths": {name: {"true": true_strength(setup, name) if name in hidden else None,
                               "fitted": recovered(setup, name, result.final["values"])}
                        for name in result.missing_effects}} if setup else {})


def table(rows, columns) -> str:
    """Markdown confusion table: rows = hidden, columns = named (counts)."""
    hidden_keys = []
    for row in rows:
        key = "+".join(row["hidden"]) or "none"
        if key not in hidden_keys:
            hidden_keys.append(key)
    lines = ["| hidden \\ named | " + " | ".join(columns) + " | correct | mean runtime (s) |",
             "|---|" + "---|" * (len(columns) + 2)]
    for key in hidden_keys:
        group = [r for r in rows if ("+".join(r["hidden"]) or "none") == key]
        counts = []
        for column in columns:
            if column == "none":
                counts.append(sum(1 for r in group if not r["named"]))
            else:
                counts.append(sum(1 for r in group if column in r["named"]))
        correct = sum(r["correct"] for r in group)
        runtime = sum(r["runtime_s"] for r in group) / len(group)
        lines.append(f"| {key} | " + " | ".join(str(c) for c in counts) + f" | {correct}/{len(group)} | {runtime:.0f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="8-bead chain, one seed, no pairs")
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--pairs", action="store_true", help="also hide the two-effect pairs")
    parser.add_argument("--n-beads", type=int, default=None)
    parser.add_argument("--noise", type=float, default=0.005, help="noise sigma / largest signal")
    parser.add_argument("--effects", default="", help="comma-separated subset of rows (default all)")
    parser.add_argument("--independent", action="store_true",
                        help="data from independent_data.py: --setups, --code-path, two pairs")
    parser.add_argument("--setups", default="paper,brass", help="with --independent [paper,brass]")
    parser.add_argument("--code-path", default="diffrax", choices=("diffrax", "verlet"))
    parser.add_argument("--out", default=None,
                        help="output folder [benchmarks/results/confusion/<case>: quick, pairs, full or independent_<code path>]")
    args = parser.parse_args(argv)
    n_beads = args.n_beads or (8 if args.quick else 21)
    contacts = (n_beads // 3, 2 * n_beads // 3)
    velocities = (0.02, 0.05, 0.12, 0.3, 0.6)
    cases = [()] + [(name,) for name in EFFECT_NAMES]
    if args.pairs and not args.quick:
        cases += list(PAIRS)
    if args.effects:
        wanted = [e.strip() for e in args.effects.split(",") if e.strip()]
        cases = [c for c in cases if ("+".join(c) or "none") in wanted]
    setups = [s.strip() for s in args.setups.split(",") if s.strip()] if args.independent else [None]
    if args.independent:
        cases = [c for c in cases if len(c) < 2] + [("viscous_damping", "wall_compliance"),
                                                     ("dashpot_damping", "track_friction")]
        if args.effects:
            cases = [c for c in cases if ("+".join(c) or "none") in wanted]
    rows = []
    began = time.perf_counter()
    total = len(cases) * args.seeds * len(setups)
    for setup in setups:
        for case in cases:
            for seed in range(args.seeds):
                row = run_case(case, 100 + seed, n_beads=n_beads, noise_fraction=args.noise, contacts=contacts,
                               velocities=velocities, setup=setup, code_path=args.code_path if setup else None)
                rows.append(row)
                print(f"[{len(rows)}/{total}] {row['setup']}: hidden {'+'.join(case) or 'none'} seed {seed}: "
                      f"named {', '.join(row['named']) or 'none'} ({row['runtime_s']:.0f} s)", flush=True)
    elapsed = time.perf_counter() - began
    columns = ["none"] + list(EFFECT_NAMES)
    # one folder per case, so the code paths' tables sit side by side
    case = f"independent_{args.code_path}" if args.independent else \
        "quick" if args.quick else "pairs" if args.pairs else "full"
    out = Path(args.out) if args.out else Path(__file__).resolve().parent / "results" / "confusion" / case
    stem = "latest"
    settings = {"n_beads": n_beads, "contacts": contacts, "velocities_m_s": velocities, "noise_fraction": args.noise,
                "seeds": args.seeds, "quick": args.quick}
    if args.independent:
        settings = {"setups": {name: {k: v for k, v in SETUPS[name].items() if k != "fields"} for name in setups},
                    "code_path": args.code_path, "seeds": args.seeds,
                    "data": "independent_data.py: 0.5 % noise, 11 bits, 2 us, piezo channels, true header velocity"}
    write_json(out / f"{stem}.json", {"settings": settings, "rows": rows, "runtime_s": elapsed})
    write_csv(out / f"{stem}.csv",
              ["setup", "code_path", "hidden", "seed", "named", "correct", "alarm", "gap_base", "gap_final",
               "runtime_s"],
              [[r["setup"], r["code_path"], "+".join(r["hidden"]) or "none", r["seed"],
                "+".join(r["named"]) or "none", r["correct"], r["alarm"], f"{r['gap_base']:.6g}",
                f"{r['gap_final']:.6g}", f"{r['runtime_s']:.1f}"] for r in rows])
    md = f"# Diagnosis confusion table\n\n{json.dumps(settings)}\n\n"
    for setup in dict.fromkeys(r["setup"] for r in rows):
        md += f"## {setup}\n\n" + table([r for r in rows if r["setup"] == setup], columns) + "\n"
    recovered_rows = [(r, effect, s) for r in rows for effect, s in r.get("strengths", {}).items()
                      if s["true"] is not None and s["fitted"] is not None]
    if recovered_rows:
        md += ("## Strengths recovered\n\n| setup | hidden | named | true | fitted | relative error |\n"
               "|---|---|---|---|---|---|\n")
        for r, effect, s in recovered_rows:
            md += (f"| {r['setup']} | {'+'.join(r['hidden'])} | {effect} | {s['true']:.5g} | {s['fitted']:.5g} | "
                   f"{(s['fitted'] - s['true']) / s['true']:+.2%} |\n")
        md += "\n"
    md += f"Total run time {elapsed:.0f} s ({len(rows)} diagnoses).\n"
    write_text(out / f"{stem}.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
