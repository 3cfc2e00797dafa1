"""`hertzchain diagnose FILE... [--model base] [--out DIR (default out/diagnose)]`: find, name and add the effects a
chain model is missing (see `fitting.diagnosis`).

Writes `DIR/diagnosis.json` (`missing_effects` in the order found, `steps` with
`gap_before`/`gap_after`, `converged` and `unconverged_fits`), `diagnosis.md`, `gaps.csv`,
`gap.png` and overlay PNGs; the folder is written as a whole and replaces the previous run's
(`hertzchain.atomic.output_folder`). Exits 3 when a fit the result rests on (a named effect's
refit, the fit adding it, the final fit) reached no optimum, as `hertzchain fit` does.
"""

from __future__ import annotations

import argparse
import sys

from pathlib import Path

from fitting.effects import EFFECT_NAMES
from fitting.model import STEPS_PER_CONTACT, ForwardModel
from hertzchain.atomic import output_folder

from . import EXIT_NOT_CONVERGED, exit_codes_epilog


def _names(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = exit_codes_epilog("a fit the result rests on (a named effect's refit, the fit adding it, "
                                      "the final fit; for driven files a named effect's fit) reached no optimum")
    parser.add_argument("files", nargs="+", metavar="FILE",
                        help="trace files (hertzchain-trace/1) or experiment files (.toml)")
    parser.add_argument("--model", default="base",
                        help="starting model: 'base' (header's chain, no dissipation, ideal force sensors) "
                        f"or 'base+EFFECT+...'; effects: {', '.join(EFFECT_NAMES)}")
    parser.add_argument("--out", default="out/diagnose", metavar="DIR", help="output folder (default: out/diagnose)")
    parser.add_argument("--free", default="", help="further parameters fitted throughout, e.g. C or eta,mu")
    parser.add_argument("--nuisances", default="striker_velocity,time_offset",
                        help="per-file/per-channel nuisances (default striker_velocity,time_offset; add gain "
                        "for uncalibrated channels)")
    parser.add_argument("--candidates", default="", help="effects to consider (default: all)")
    parser.add_argument("--channels", default="", help="channels to use (default: all of each file)")
    parser.add_argument("--max-effects", type=int, default=3, help="most effects to add (default 3)")
    parser.add_argument("--min-share", type=float, default=0.2,
                        help="share of the remaining excess misfit a named effect must remove (default 0.2)")
    parser.add_argument("--steps-per-contact", type=int, default=STEPS_PER_CONTACT,
                        help=f"Verlet steps per shortest contact time of the model (default {STEPS_PER_CONTACT}, "
                        "as for fit: see fitting.model)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    parser.add_argument("--data-dir", help="driven experiments (kind = \"driven\"): the folder their sweep files "
                        "are relative to")
    parser.add_argument("--no-compile-cache", action="store_true",
                        help="do not keep compiled code between runs (default: kept in $HERTZCHAIN_CACHE/jax, "
                        "~/.cache/hertzchain/jax; also off with HERTZCHAIN_NO_COMPILE_CACHE=1)")


def run(args) -> int:
    from fitting.compilation_cache import enable_compilation_cache
    from fitting.driven_cli import is_driven_run, run_diagnose as run_driven_diagnose

    enable_compilation_cache(not args.no_compile_cache)
    if args.max_effects < 0:
        raise ValueError("--max-effects must be >= 0.")
    if not 0 <= args.min_share < 1:
        raise ValueError("--min-share must be in [0, 1).")
    ForwardModel(steps_per_contact=args.steps_per_contact)  # refuses a step count the solver cannot run
    # driven experiment files (lock-in sweeps of a driven chain) have their own diagnosis
    driven = is_driven_run(args.files, args.data_dir)
    with output_folder(args.out, "diagnose", "diagnosis.json") as out:
        if driven:
            return run_driven_diagnose(args, out)
        return _diagnose(args, out)


def _diagnose(args, out: Path) -> int:
    """The diagnosis of trace files, written into `out` (the temporary of `--out`)."""
    from fitting.data import load_experiments
    from fitting.diagnosis import diagnose
    from fitting.diagnosis_report import readings, write_diagnosis_report

    experiments = load_experiments(args.files, channels=_names(args.channels) or None)
    diagnosis = diagnose(
        experiments, model=args.model, free=_names(args.free), nuisances=_names(args.nuisances),
        candidates=_names(args.candidates) or None, max_effects=args.max_effects,
        min_share=args.min_share, steps_per_contact=args.steps_per_contact, progress=not args.quiet,
    )
    paths = write_diagnosis_report(diagnosis, out)
    final = {key: Path(args.out) / Path(path).name for key, path in paths.items()}
    print(f"missing effects: {', '.join(diagnosis.missing_effects) or 'none'}")
    print(diagnosis.conclusion)
    for line in readings(diagnosis):
        print(f"  {line}")
    print(f"report: {final['markdown']} (JSON {final['json']})", file=sys.stderr if args.quiet else sys.stdout)
    if not diagnosis.converged:
        print(f"hertzchain diagnose: error: no optimum reached by {'; '.join(diagnosis.unconverged)}.",
              file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0
