"""`hertzchain diagnose FILE... [--model base] [--out DIR (default out/diagnose)]`: find, name and add the effects a
chain model is missing (see `fitting.diagnosis`).

A driven experiment file (`kind = "driven"`: a bending `[sweep]`, or `[[measurement]]` tables of
bending, tongue, loop and scope runs; `docs/how-to/driven-measurements.md`) runs the candidate-law
protocol instead (`fitting.driven.diagnosis`): each candidate law fitted on the bending run, named
only where it predicts a measurement it was not fitted on (the held-out top drive levels, the
tongue's tip, the loop's onset) better than the base. `--candidates` names driven candidates
there; `--held-out-levels`, `--level-stride` and `--max-steps` are its cost knobs.

Writes `DIR/diagnosis.json` (`missing_effects` in the order found, `steps` with
`gap_before`/`gap_after`, `converged` and `unconverged_fits`), `diagnosis.md`, `gaps.csv`,
`gap.png` and overlay PNGs; the folder is written as a whole and replaces the previous run's
(`hertzchain.io.atomic.output_folder`). Exits 3 when a fit the result rests on (a named effect's
refit, the fit adding it, the final fit) reached no optimum, as `hertzchain fit` does.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fitting.driven.candidates import CANDIDATES, SLOW_CANDIDATES
from fitting.driven.diagnosis import (
    DEFAULT_HELD_OUT_LEVELS,
    DEFAULT_LEVEL_STRIDE,
    DEFAULT_MAX_STEPS,
)
from fitting.effects import EFFECT_NAMES
from fitting.model import STEPS_PER_CONTACT, ForwardModel

from ..io.atomic import output_folder
from .errors import EXIT_NOT_CONVERGED, exit_codes_epilog
from .shared_options import add_compile_cache_option, add_driven_data_dir_option


def _names(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def _parameters(text: str, option: str) -> list[str]:
    """The public names of the parameters listed in `option` (either spelling; a previous
    name warns once, naming `option`, as in `hertzchain fit`: `fitting.parameters.resolve_name`),
    as the library takes them."""
    from fitting.parameters import public_label, resolve_name

    return [public_label(resolve_name(name, where=option)) for name in _names(text)]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = exit_codes_epilog("a fit the result rests on (a named effect's refit, the fit adding it, "
                                      "the final fit; for driven files a candidate law's fit) reached no optimum")
    parser.add_argument("files", nargs="+", metavar="FILE",
                        help="trace files (hertzchain-trace/1) or experiment files (.toml)")
    parser.add_argument("--model", default="base",
                        help="starting model: 'base' (header's chain, no dissipation, ideal force sensors) "
                        f"or 'base+EFFECT+...'; effects: {', '.join(EFFECT_NAMES)}")
    parser.add_argument("--out", default="out/diagnose", metavar="DIR", help="output folder (default: out/diagnose)")
    parser.add_argument("--free", default="", help="further parameters fitted throughout, e.g. C or eta_s,mu")
    parser.add_argument("--nuisances", default="striker_velocity_m_s,time_offset_s",
                        help="per-file/per-channel nuisances (default striker_velocity_m_s,time_offset_s; add "
                        "gain for uncalibrated channels)")
    parser.add_argument("--candidates", default="",
                        help="effects to consider (default: all); driven files: candidate laws, of "
                        f"{', '.join(c.name for c in CANDIDATES + SLOW_CANDIDATES)} (default: all but "
                        f"{', '.join(c.name for c in SLOW_CANDIDATES)}, whose sliders run the slow JAX kernel)")
    parser.add_argument("--channels", default="", help="channels to use (default: all of each file)")
    parser.add_argument("--max-effects", type=int, default=3, help="most effects to add (default 3)")
    parser.add_argument("--min-share", type=float, default=0.2,
                        help="share of the remaining excess misfit a named effect must remove (default 0.2)")
    parser.add_argument("--steps-per-contact", type=int, default=STEPS_PER_CONTACT,
                        help=f"Verlet steps per shortest contact time of the model (default {STEPS_PER_CONTACT}, "
                        "as for fit: see fitting.model)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_driven_data_dir_option(parser)
    parser.add_argument("--held-out-levels", type=int, default=DEFAULT_HELD_OUT_LEVELS,
                        help="driven files: the bending run's top drive levels each candidate is not fitted on "
                        f"and predicts (default {DEFAULT_HELD_OUT_LEVELS}; at least 1)")
    parser.add_argument("--level-stride", type=int, default=DEFAULT_LEVEL_STRIDE,
                        help="driven files: each candidate's bending fit uses every k-th of the other drive "
                        f"levels (default {DEFAULT_LEVEL_STRIDE}: the single bead's bending, tongue and loop "
                        "with the default candidates within 10 minutes on 2 cores; 1 fits every level)")
    parser.add_argument("--max-steps", type=int, default=DEFAULT_MAX_STEPS,
                        help=f"driven files: optimiser iterations per candidate (default {DEFAULT_MAX_STEPS})")
    add_compile_cache_option(parser)


def run(args) -> int:
    from fitting.compilation_cache import enable_compilation_cache

    from .driven_experiments import is_driven_run, refuse_driven_diagnose_options
    from .driven_experiments import run_diagnose as run_driven_diagnose

    enable_compilation_cache(not args.no_compile_cache)
    if args.max_effects < 0:
        raise ValueError("--max-effects must be >= 0.")
    if not 0 <= args.min_share < 1:
        raise ValueError("--min-share must be in [0, 1).")
    ForwardModel(steps_per_contact=args.steps_per_contact)  # refuses a step count the solver cannot run
    # driven experiment files run the candidate-law protocol
    driven = is_driven_run(args.files, args.data_dir)
    if not driven:
        refuse_driven_diagnose_options(args)
    with output_folder(args.out, "diagnose", "diagnosis.json") as out:
        if driven:
            return run_driven_diagnose(args, out)
        return _diagnose(args, out)


def _diagnose(args, out: Path) -> int:
    """The diagnosis of trace files, written into `out` (the temporary of `--out`)."""
    from fitting.data import load_experiments
    from fitting.diagnosis import diagnose
    from fitting.diagnosis.report import readings, write_diagnosis_report

    experiments = load_experiments(args.files, channels=_names(args.channels) or None)
    diagnosis = diagnose(
        experiments, model=args.model, free=_parameters(args.free, "--free"),
        nuisances=_parameters(args.nuisances, "--nuisances"),
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
