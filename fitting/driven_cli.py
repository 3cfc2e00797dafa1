"""`hertzchain fit` and `hertzchain diagnose` on driven experiment files (`kind = "driven"`).

`fitting/cli/fit.py` and `fitting/cli/diagnose.py` hand their arguments here when every file
given is a driven experiment; the options that only trace fits have are refused by name when
given, so that nothing the user asked for is silently dropped.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from hertzchain.units import format_measured

from .driven_experiment import is_driven_experiment, load_driven_experiment

# Defaults of the trace-fit options: a driven run accepts an option only at its default.
_FIT_DEFAULTS = {"multistart": 1, "profile": "", "start": None, "fixed": None, "channels": None,
                 "noise_std": None, "covariance": "auto", "prior": [], "posterior": False}
_DIAGNOSE_DEFAULTS = {"model": "base", "free": "", "nuisances": "striker_velocity,time_offset",
                      "candidates": "", "channels": ""}
DEFAULT_FREE = ("linear_resonance_hz", "precompression_n", "damping_rate_per_s", "drive_scale")


def is_driven_run(files, data_dir=None) -> bool:
    """Whether the command's files are driven experiments (all of them; a mix is an error, and
    so is `data_dir` given for trace files)."""
    driven = [is_driven_experiment(f) for f in files]
    if any(driven) and not all(driven):
        raise ValueError("driven experiment files (kind = \"driven\") cannot be mixed with trace files in one run.")
    if data_dir is not None and not all(driven):
        raise ValueError("--data-dir is for driven experiment files (kind = \"driven\"); trace files name their own paths.")
    return bool(driven) and all(driven)


def _refuse(args, defaults, command):
    given = [name for name, default in defaults.items() if getattr(args, name, default) != default]
    if given:
        options = ", ".join("--" + name.replace("_", "-") for name in given)
        raise ValueError(f"{options}: not available for driven experiments in `hertzchain {command}`; leave them out.")


def _one_experiment(args):
    if len(args.files) != 1:
        raise ValueError("driven experiments are fitted one file at a time; give one experiment file.")
    return load_driven_experiment(args.files[0], args.data_dir)


def run_fit(args, out) -> int:
    """The driven branch of `hertzchain fit`, written into the folder `out` (exit 0 converged, 3 not
    converged)."""
    from .driven import PARAMETERS, fit_driven
    from .driven_report import report_data, write_driven_report

    _refuse(args, _FIT_DEFAULTS, "fit")
    free = DEFAULT_FREE
    if args.params != "eta,mu,C":  # the trace fit's default: not asked for
        free = tuple(p.strip() for p in args.params.split(",") if p.strip())
        unknown = [p for p in free if p not in PARAMETERS]
        if unknown:
            raise ValueError(f"--params: {', '.join(unknown)} not driven parameters; valid: {', '.join(PARAMETERS)}.")
    experiment = _one_experiment(args)
    result = fit_driven(experiment, free=free, max_steps=args.max_steps, progress=not args.quiet)
    write_driven_report(result, out, data_dir=args.data_dir, plots=not args.no_plots)
    data = report_data(result, data_dir=args.data_dir)
    for name, p in data["params"].items():
        if p["fitted"]:
            stderr = math.nan if p["stderr"] is None else p["stderr"]
            print(f"{name} = {format_measured(p['value'], stderr, p['unit'])}")
    print(f"misfit: median {100 * data['misfit']['median']:.2f} %, max {100 * data['misfit']['max']:.2f} % of "
          f"each curve's peak; residual lag-1 correlation {result.rho:.3f}")
    for mode in data["bending"]:
        print(f"mode {mode['mode']}: resonance shift measured {100 * mode['measured']['shift']:.2f} %, "
              f"model {100 * mode['model']['shift']:.2f} %")
    print(f"wrote fit.json, curves.csv{'' if args.no_plots else ', fit.png'} to {args.out} "
          f"({result.elapsed_s:.0f} s)")
    if not result.converged:
        print("hertzchain fit: error: the optimiser did not reach an optimum; raise --max-steps.", file=sys.stderr)
        return 3
    return 0


def run_diagnose(args, out) -> int:
    """The driven branch of `hertzchain diagnose`, written into the folder `out` (exit 0
    converged, 3 not converged)."""
    from .driven_diagnosis import diagnose_driven, write_driven_diagnosis

    _refuse(args, _DIAGNOSE_DEFAULTS, "diagnose")
    experiment = _one_experiment(args)
    diagnosis = diagnose_driven(experiment, max_effects=args.max_effects, min_share=args.min_share,
                                progress=not args.quiet)
    paths = write_driven_diagnosis(diagnosis, out)
    print(f"missing effects: {', '.join(diagnosis['missing_effects']) or 'none'}")
    print(diagnosis["conclusion"])
    print(f"report: {Path(args.out) / paths[0].name}")
    if not diagnosis["converged"]:
        print(f"hertzchain diagnose: error: no optimum reached by {'; '.join(diagnosis['unconverged_fits'])} "
              "(their values are the last iterate's).", file=sys.stderr)
        return 3
    return 0
