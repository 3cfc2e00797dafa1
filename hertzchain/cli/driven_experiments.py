"""`hertzchain fit` and `hertzchain diagnose` on driven experiment files (`kind = "driven"`).

`hertzchain/cli/fit.py` and `hertzchain/cli/diagnose.py` hand their arguments here when every
file given is a driven experiment; the options that only trace fits have are refused by name
when given (and the driven diagnosis's own options for trace files), so that nothing the user
asked for is silently dropped. The keys of a driven experiment file:
`docs/how-to/driven-measurements.md`.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from fitting.driven.experiment import is_driven_experiment, load_driven_experiment

from ..units import format_measured
from .errors import EXIT_NOT_CONVERGED

# The options of `fit` and `diagnose` that only trace files take: a driven run accepts each only at
# the command's own default (read from its parser, `_defaults`).
_TRACE_FIT_OPTIONS = ("multistart", "profile", "start", "fixed", "channels", "noise_std", "covariance", "prior",
                      "posterior")
_TRACE_DIAGNOSE_OPTIONS = ("model", "free", "nuisances", "channels", "max_effects", "min_share", "steps_per_contact")
# The options of `diagnose` that only driven files take (the candidate protocol's cost knobs).
DRIVEN_DIAGNOSE_OPTIONS = ("held_out_levels", "level_stride", "max_steps")
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


def _defaults(command: str, names) -> dict:
    """The defaults of `hertzchain COMMAND`'s options `names`, as its parser sets them."""
    import argparse
    import importlib

    parser = argparse.ArgumentParser()
    importlib.import_module(f"hertzchain.cli.{command}").add_arguments(parser)
    return {name: parser.get_default(name) for name in names}


def _refuse(args, names, command, *, kind="driven experiments"):
    """Refuse the options `names` of `hertzchain COMMAND` given at other than their defaults,
    as not available for `kind`."""
    defaults = _defaults(command, names)
    given = [name for name, default in defaults.items() if getattr(args, name, default) != default]
    if given:
        options = ", ".join("--" + name.replace("_", "-") for name in given)
        raise ValueError(f"{options}: not available for {kind} in `hertzchain {command}`; leave them out.")


def refuse_driven_diagnose_options(args) -> None:
    """`hertzchain diagnose` on trace files: refuse the driven protocol's options by name."""
    _refuse(args, DRIVEN_DIAGNOSE_OPTIONS, "diagnose", kind="trace files")


def _one_experiment(args):
    if len(args.files) != 1:
        raise ValueError("driven experiments are fitted one file at a time; give one experiment file.")
    return load_driven_experiment(args.files[0], args.data_dir)


def run_fit(args, out) -> int:
    """The driven branch of `hertzchain fit`, written into the folder `out` (exit 0 converged, 3 not
    converged)."""
    from fitting.driven.lockin_fit import PARAMETERS, fit_driven
    from fitting.driven.report import report_data, write_driven_report

    _refuse(args, _TRACE_FIT_OPTIONS, "fit")
    experiment = _one_experiment(args)
    if experiment.measurements:
        return run_joint_fit(args, out, experiment)
    free = DEFAULT_FREE
    if args.params != _defaults("fit", ("params",))["params"]:  # the trace fit's default: not asked for
        free = tuple(p.strip() for p in args.params.split(",") if p.strip())
        unknown = [p for p in free if p not in PARAMETERS]
        if unknown:
            raise ValueError(f"--params: {', '.join(unknown)} not driven parameters; valid: {', '.join(PARAMETERS)}.")
    result = fit_driven(experiment, free=free, max_steps=args.max_steps, progress=not args.quiet)
    write_driven_report(result, out, data_dir=args.data_dir, plots=not args.no_plots)
    data = report_data(result, data_dir=args.data_dir)
    for name, p in data["params"].items():
        if not p["fitted"]:
            continue
        values, errors = (p[key] if isinstance(p[key], list) else [p[key]] for key in ("value", "stderr"))
        for k, (value, stderr) in enumerate(zip(values, errors)):  # one per mode where the parameter has several
            label = name if len(values) == 1 else f"{name}[{k + 1}]"
            print(f"{label} = {format_measured(value, math.nan if stderr is None else stderr, p['unit'])}")
    print(f"misfit: median {100 * data['misfit']['median']:.2f} %, max {100 * data['misfit']['max']:.2f} % of "
          f"each curve's peak; residual lag-1 correlation {result.rho:.3f}")
    for mode in data["bending"]:
        print(f"mode {mode['mode']}: resonance shift measured {100 * mode['measured']['shift']:.2f} %, "
              f"model {100 * mode['model']['shift']:.2f} %")
    print(f"wrote fit.json, curves.csv{'' if args.no_plots else ', fit.png'} to {args.out} "
          f"({result.elapsed_s:.0f} s)")
    print(f"{result.message}; chi^2/dof {result.reduced_chi2:.4g} ({result.steps} steps, kernel "
          f"{result.kernel['name']})")
    if not result.converged:
        print(f"hertzchain fit: error: {result.message}", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


def run_joint_fit(args, out, experiment) -> int:
    """`hertzchain fit` on a file of `[[measurement]]` tables: every measurement fitted together,
    the constants its `[fit]` table names shared or per run (exit 0 converged, 3 not)."""
    from fitting.driven.joint import fit_joint
    from fitting.driven.joint_report import report_data, write_joint_report

    if args.params != _defaults("fit", ("params",))["params"]:
        raise ValueError("--params: a file of [[measurement]] tables names what it fits in its [fit] table "
                         "(shared = [...], per_run = [...]); leave --params out.")
    result = fit_joint(experiment, max_steps=args.max_steps, progress=not args.quiet)
    write_joint_report(result, out, data_dir=args.data_dir)
    data = report_data(result, data_dir=args.data_dir)
    for label, p in data["params"].items():
        where = "shared" if p["shared"] else "per run"
        value = p["value"][0] if isinstance(p["value"], list) else p["value"]
        stderr = p["stderr"][0] if isinstance(p["stderr"], list) else p["stderr"]
        open_ = "" if p["determined"] else " (not determined by the data)"
        print(f"{label} ({where}) = {format_measured(value, math.nan if stderr is None else stderr, p['unit'])}{open_}")
    for m in data["measurements"]:
        print(_measurement_line(m))
    print(f"{data['status']['message']}; wrote fit.json to {args.out} ({result.elapsed_s:.0f} s)")
    if not result.converged:
        print("hertzchain fit: error: the optimiser did not reach an optimum; raise --max-steps.", file=sys.stderr)
        return 3
    return 0


def _nm(value) -> str:
    return "none" if value is None or not math.isfinite(value) else f"{value * 1e9:.1f} nm"


def _measurement_line(m: dict) -> str:
    if m["kind"] == "bending":
        return (f"bending ({m['run']}): misfit median {100 * m['misfit']['median']:.2f} %, shift measured "
                f"{100 * m['measured']['shift']:.2f} %, model {100 * m['model']['shift']:.2f} %")
    if m["kind"] == "tongue":
        data, model = m["measured_tip"], m["model_tip"]
        at = f" at {model['frequency_hz']:.0f} Hz" if model["frequency_hz"] else ""
        alone = m["bending_alone_tip"]
        alone_at = f" at {alone['frequency_hz']:.0f} Hz" if alone["frequency_hz"] else ""
        return (f"tongue ({m['run']}): tip measured {_nm(data['amplitude_m'])} at {data['frequency_hz']:.0f} Hz, "
                f"model {_nm(model['amplitude_m'])}{at} (the bending run's constants alone: "
                f"{_nm(alone['amplitude_m'])}{alone_at})")
    if m["kind"] == "loop":
        return (f"loop ({m['run']}, {m['frequency_hz']:.0f} Hz): f/2 going up measured at "
                f"{_nm(m['measured_onset_up_m'])}, model {_nm(m['model_onset_up_m'])} (the bending run's constants "
                f"alone: {_nm(m['bending_alone_onset_up_m'])}); coming down it persists to "
                f"{_nm(m['measured_last_down_m'])}, in the model's loop (time-stepped, not fitted) to "
                f"{_nm(m['model_loop']['last_down_m'])}")
    return (f"scope ({m['run']}): f/2 in {m['records_with_subharmonic']} of {m['records']} records, from "
            f"{_nm(m['onset_up_m'])} going up (a check, not fitted)")


def run_diagnose(args, out) -> int:
    """The driven branch of `hertzchain diagnose`: the candidate-law protocol
    (`fitting.driven.diagnosis.diagnose_experiment`) on one experiment file, bending-only or of
    `[[measurement]]` tables, written into the folder `out` (exit 0 converged, 3 a candidate's
    fit did not converge)."""
    from fitting.driven.diagnosis import (
        candidates_named,
        diagnose_experiment,
        write_driven_diagnosis,
    )

    _refuse(args, _TRACE_DIAGNOSE_OPTIONS, "diagnose")
    candidates = candidates_named([n.strip() for n in args.candidates.split(",") if n.strip()])
    experiment = _one_experiment(args)
    diagnosis = diagnose_experiment(experiment, candidates, held_out_levels=args.held_out_levels,
                                    level_stride=args.level_stride, max_steps=args.max_steps,
                                    progress=not args.quiet)
    paths = write_driven_diagnosis(diagnosis, out)
    print(f"named: {', '.join(diagnosis['verdict']['named']) or 'none'}")
    print(diagnosis["conclusion"])
    print(f"report: {Path(args.out) / paths[1].name} (JSON {Path(args.out) / paths[0].name}; "
          f"{diagnosis['elapsed_s']:.0f} s)")
    if not diagnosis["converged"]:
        print(f"hertzchain diagnose: error: no optimum reached by {'; '.join(diagnosis['unconverged_fits'])} "
              "(their values are the last iterate's; raise --max-steps).", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0
