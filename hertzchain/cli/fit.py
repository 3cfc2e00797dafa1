"""`hertzchain fit FILE... --params eta_s,mu,C`: fit parameters to trace files.

The chain of each file is described by its header (see `hertzchain.io.tracefile`); the
command fits the chosen parameters and writes `fit.json`, CSV tables and PNG plots
(`fitting.report`) into `--out`, written as a whole: a temporary folder beside it replaces
the previous run's folder when the command ends (`hertzchain.io.atomic.output_folder`).
`--prior` (and an experiment file's `[prior]` table) states a lab's tolerances
(`fitting.priors`): each frees its parameter and the optimum is the MAP point. Parameters
are named as everywhere a user sees them (`fitting.parameters.public_names`: `eta_s`,
`wall_youngs_pa`, `striker_velocity_m_s[run1]`, `mu`, `C`); a previous short name (`eta`,
`wall_youngs`) still works for one release, with a one-line warning.
`--posterior` then samples the posterior by NUTS (`fitting.posterior`) and writes
`posterior.json`, `posterior.nc`, `draws.csv`, `posterior_summary.md` and plots
(`fitting.posterior_report`) beside the fit's files. Exit status: 0 converged, 3 not
converged (the report is still written, marked `"converged": false`), 4 the posterior's
diagnostics fail and `--strict` was given, 2 bad input.

Plots: one summary figure (`fit_summary.png`) by default, an overlay and a residual figure per
file with `--per-trace-plots`. Wall time: `timings.json` gives the seconds spent reading,
fitting (compilation and iterations) and writing. Compiled code is kept between runs
(`fitting.compilation_cache`: `$HERTZCHAIN_CACHE/jax`, default `~/.cache/hertzchain/jax`), so
a second fit of files of the same shapes skips most of the compilation; `--no-compile-cache`
or `HERTZCHAIN_NO_COMPILE_CACHE=1` turns that off.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

from fitting.compilation_cache import enable_compilation_cache, jax_cache_on
from fitting.data import load_experiments
from fitting.effects import PREFIX as EFFECT_PREFIX
from fitting.fit import FitWarning, fit
from fitting.forward_model import time_step_s
from fitting.model import STEPS_PER_CONTACT, ForwardModel
from fitting.parameters import (
    build_instances,
    checked_keys,
    get_spec,
    parse_parameter_list,
    public_label,
    public_names,
    resolve_label,
)
from fitting.posterior import PosteriorWarning, sample_posterior
from fitting.posterior_report import write_posterior_report
from fitting.priors import parse_priors, prior_names
from fitting.report import summary_text, write_report
from fitting.uncertainty import COVARIANCES

from ..io.atomic import output_folder, write_json
from ..io.importer import experiment_priors
from ..timegrid import choose_time_grid
from ..units import counted, parse_quantity
from ..validation import RunSize, check_run_size, estimate_run_size
from .shared_options import add_compile_cache_option, add_driven_data_dir_option


def _assignments(text: str | None, option: str) -> dict:
    """Parse 'eta_s=2us,mu=0.19' into {public label: SI value}, as the library takes it
    (units by the parameter's unit; either spelling of a name, `fitting.parameters.resolve_label`:
    a previous name warns, naming `option`)."""
    values = {}
    if not text:
        return values
    for part in text.split(","):
        if not part.strip():
            continue
        if "=" not in part:
            raise ValueError(f"{option}: expected name=value pairs, got {part!r}.")
        written, value = (s.strip() for s in part.split("=", 1))
        name = resolve_label(written, where=option)
        spec = get_spec(name.split("[", 1)[0])
        unit = spec.unit if spec.unit in ("s", "Pa", "N", "m/s") else ""
        values[public_label(name)] = parse_quantity(value, unit, name=f"{option} {written}")
    return values


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE",
                        help="trace files (hertzchain-trace/1) or experiment files (.toml)")
    parser.add_argument(
        "--params", default="eta_s,mu,C",
        help="comma-separated parameters to fit [eta_s,mu,C]; valid: "
        + ", ".join(name for name in public_names() if not name.startswith(EFFECT_PREFIX))
        + ". A driven experiment (kind = \"driven\") with one [sweep]: linear_resonance_hz, precompression_n, "
        "damping_rate_per_s, drive_scale, eta_s [the first four]; one of [[measurement]] tables (bending, tongue, "
        "loop, scope) names its shared and per-run constants in its [fit] table instead (any positive "
        "DrivenChain field, e.g. contact_kappa_n_m1p5, and drive_scale)",
    )
    parser.add_argument("--out", default="out/fit", help="output folder [out/fit]")
    parser.add_argument("--multistart", type=int, default=1, help="starts run as one batch [1]")
    parser.add_argument("--seed", type=int, default=0, help="seed of the spread starts [0]")
    parser.add_argument("--profile", default="", help="parameters to profile, e.g. eta_s,mu")
    parser.add_argument("--start", help="start values, e.g. eta_s=2us,mu=0.1 [from the data]")
    parser.add_argument("--fixed", help="hold global parameters at values, e.g. mu=0.19,wall_youngs_pa=5GPa")
    parser.add_argument("--channels", help="channels to fit, e.g. contact_6,wall [all]")
    parser.add_argument("--noise-std", help="noise sigma of every channel (N) [header, else estimated]")
    parser.add_argument(
        "--covariance", choices=COVARIANCES, default="auto",
        help="standard errors from the stated noise, scaled by chi^2/dof, or from the residuals' own "
        "sample-to-sample covariance (correlated); auto chooses (fitting.uncertainty) [auto]",
    )
    parser.add_argument("--max-steps", type=int, default=100, help="optimiser iterations per start [100]")
    parser.add_argument(
        "--steps-per-contact", type=int, default=STEPS_PER_CONTACT,
        help=f"Verlet steps per shortest contact time [{STEPS_PER_CONTACT}]",
    )
    parser.add_argument(
        "--prior", action="append", default=[], metavar="NAME=VALUE",
        help="a tolerance, e.g. bead_youngs_pa=203GPa+-4GPa, sensor_gain=+-2%%, bead_radius_m=+-62.5um, "
        "eta_s=0..10us (repeat the option; frees the parameter)",
    )
    parser.add_argument("--posterior", action="store_true",
                        help="sample the posterior by NUTS after the fit (posterior.json, draws, plots)")
    parser.add_argument("--chains", type=int, default=4, help="posterior: chains, run as one batch [4]")
    parser.add_argument("--warmup", type=int, default=100, help="posterior: warmup iterations per chain [100]")
    parser.add_argument("--draws", type=int, default=200, help="posterior: kept draws per chain [200]")
    parser.add_argument("--adapt-metric", action="store_true",
                        help="posterior: adapt a diagonal metric during warmup as well")
    parser.add_argument("--strict", action="store_true",
                        help="posterior: exit with status 4 when R-hat, ESS or divergences fail")
    parser.add_argument("--no-plots", action="store_true", help="write JSON and CSV only")
    parser.add_argument("--per-trace-plots", action="store_true",
                        help="also an overlay and a residual figure per file (about 1.5 s each) besides the "
                        "summary figure fit_summary.png")
    add_compile_cache_option(parser)
    parser.add_argument("--yes", action="store_true",
                        help="fit even when one iteration (the model and its derivatives for every file and "
                        "start) needs more memory than is available or more than 1e10 bead-steps")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    add_driven_data_dir_option(parser)


def _noise_std_n(text: str | None) -> float | None:
    """`--noise-std` in N, or None; refused unless positive and finite."""
    if text is None:
        return None
    noise = parse_quantity(text, "N", name="--noise-std")
    if not (math.isfinite(noise) and noise > 0):
        raise ValueError(f"--noise-std {text}: the noise sigma must be positive (N), e.g. --noise-std 0.02N; "
                         "leave it out to use the files' noise_std_n headers or an estimate from each record.")
    return noise


def _check_counts(args) -> None:
    """Refuse counts that cannot be run (before any work starts)."""
    for option in ("max_steps", "multistart", "chains", "warmup", "draws"):
        if getattr(args, option) < 1:
            raise ValueError(f"--{option.replace('_', '-')} {getattr(args, option)}: give a positive integer.")


def check_fit_size(experiments, n_free: int, *, multistart: int, steps_per_contact: int,
                   memory_bytes: int | None = None) -> None:
    """Refuse, before the first simulation, a fit whose one iteration cannot run here: every
    file simulated at the fit's time step (`fitting.forward_model.time_step_s`) with
    `n_free` forward-mode derivatives, for each of `multistart` starts at once; its recorded
    channels (with their derivatives) must fit in the memory available (`memory_bytes`,
    default the machine's) and its bead-steps stay below `validation.MAX_BODY_STEPS`
    (`validation.check_run_size`). One line names the options that shrink it and `--yes`."""
    memory, body_steps = 0.0, 0.0
    for experiment in experiments:
        setup = experiment.trace.setup()
        times = experiment.time_s
        interval = float(times[1] - times[0]) if len(times) > 1 else float(times[-1])
        grid = choose_time_grid(setup, t_end_s=float(times[-1]), sample_interval_s=interval,
                                dt_s=time_step_s(setup, interval, steps_per_contact=steps_per_contact))
        size = estimate_run_size(n_runs_in_memory=multistart, n_runs=multistart,
                                 n_bodies=setup.n_beads + 1 + len(setup.sensor_beads),
                                 n_channels=len(experiment.channels) * (1 + n_free), n_samples=grid.n_samples,
                                 n_steps=grid.n_steps * (1 + n_free))
        memory, body_steps = memory + size.memory_bytes, body_steps + size.body_steps
    check_run_size(RunSize(memory, body_steps), memory_bytes=memory_bytes, what="one iteration of this fit",
                   smaller=("fit fewer files, --channels or a smaller --multistart",
                            "fit fewer files or parameters, lower --steps-per-contact or --multistart"))


def run(args: argparse.Namespace) -> int:
    began = time.perf_counter()
    enable_compilation_cache(not args.no_compile_cache)
    missing = [f for f in args.files if not Path(f).is_file()]
    if missing:
        raise FileNotFoundError(f"no such trace file: {', '.join(missing)}")
    _check_counts(args)
    forward = ForwardModel(steps_per_contact=args.steps_per_contact)
    noise = _noise_std_n(args.noise_std)
    # driven experiment files (lock-in sweeps of a driven chain) have their own fit
    from .driven_experiments import is_driven_run
    from .driven_experiments import run_fit as run_driven_fit

    driven = is_driven_run(args.files, args.data_dir)
    with output_folder(args.out, "fit", "fit.json") as out:
        if driven:
            return run_driven_fit(args, out)
        return _fit(args, out, began, forward, noise)


def _fit(args, out: Path, began: float, forward: ForwardModel, noise: float | None) -> int:
    """The fit of trace files, written into `out` (the temporary of `--out`)."""
    keys = parse_parameter_list(args.params, where="--params")
    params = tuple(map(public_label, keys))  # as the library takes them: a previous name has warned here
    channels = tuple(c.strip() for c in args.channels.split(",") if c.strip()) if args.channels else None
    experiments = load_experiments(args.files, channels=channels, noise_std_n=noise)
    read = time.perf_counter()
    profile = tuple(public_label(resolve_label(p.strip(), where="--profile"))
                    for p in args.profile.split(",") if p.strip())
    priors = parse_priors(parse_priors(experiment_priors(args.files), source="an experiment file's [prior]")
                          + parse_priors(args.prior, source="--prior"))  # once more: one prior per parameter
    if args.posterior and args.covariance == "residual":
        raise ValueError("--posterior samples the likelihood of the stated noise; use --covariance auto or noise.")
    if not args.yes:
        free = build_instances(checked_keys(keys + prior_names(priors)), experiments)
        check_fit_size(experiments, len(free),
                       multistart=args.multistart, steps_per_contact=args.steps_per_contact)
    print(f"fitting {', '.join(params)} to {counted(len(experiments), 'file')} ...", flush=True)
    with warnings.catch_warnings():  # the summary below and fit.json carry every warning
        warnings.simplefilter("ignore", FitWarning)
        result = fit(
            experiments, params, start=_assignments(args.start, "--start"),
            fixed=_assignments(args.fixed, "--fixed"), multistart=args.multistart, seed=args.seed,
            max_steps=args.max_steps, covariance="noise" if args.posterior else args.covariance,
            profile=profile, forward=forward,
            progress=not args.quiet, throw=False, priors=priors,
        )
    fitted = time.perf_counter()
    written = write_report(result, out, plots=not args.no_plots, per_trace=args.per_trace_plots)
    timings = {"reading_s": read - began, "fit_s": fitted - read, "writing_s": time.perf_counter() - fitted,
               "since_start_s": time.perf_counter() - began, "fit_iterations": result.n_steps,
               "compile_cache": bool(jax_cache_on())}
    write_json(out / "timings.json", timings)
    written.append(out / "timings.json")
    print(summary_text(result))
    print(f"wrote {counted(len(written), 'file')} to {args.out} (fit.json, params.csv, plots)")
    if not result.converged:
        print(f"hertzchain fit: error: {result.message}", file=sys.stderr)
        return 3
    if not args.posterior:
        return 0
    print(f"sampling the posterior: {counted(args.chains, 'chain')} x ({args.warmup} warmup + {counted(args.draws, 'draw')}) ...",
          flush=True)
    with warnings.catch_warnings():  # posterior.json and the summary carry every warning
        warnings.simplefilter("ignore", PosteriorWarning)
        posterior = sample_posterior(
            experiments, params, priors=priors, chains=args.chains, warmup=args.warmup,
            draws=args.draws, seed=args.seed, adapt_metric=args.adapt_metric,
            progress=not args.quiet, fit_result=result,
        )
    written = write_posterior_report(posterior, out, plots=not args.no_plots)
    print((out / "posterior_summary.md").read_text())
    print(f"wrote {counted(len(written), 'file')} to {args.out} (posterior.json, posterior.nc, draws.csv, plots)")
    failed = posterior.failed_diagnostics()
    if failed:
        print("hertzchain fit: WARNING: the posterior's diagnostics fail: " + "; ".join(failed)
              + ". Do not use these intervals; raise --warmup/--draws or --chains.", file=sys.stderr)
        if args.strict:
            return 4
    return 0
