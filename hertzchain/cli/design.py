"""`hertzchain design`: predicted standard errors and correlations of fitted parameters for
an experiment plan (Cramér–Rao), and the best plan of a given size.

The plan is given as trace files (headers, channels, time axes and noise define the
experiments) or by options (`--velocities 0.05,0.3 --contacts 6,11 --noise-std 0.5
--sample-interval 1us --t-end 2.5ms`; the wall is recorded unless `--no-wall`). Parameter
values at which the design is made come from the setup options (`--eta 1.7us --mu 0.12
--mu-star 0.03`). Nuisances (striker velocity, trigger offset, gains) are fixed unless
named in `--nuisances` (then free and marginalised). Writes `design.json`, `design.csv`
and `design.png` into `--out`. Parameters are named as `hertzchain fit` names them
(`fitting.parameters.public_names`: `eta_s`, `mu`, `C`, `wall_youngs_pa`,
`striker_velocity_m_s`), in the options and in every file and line written; a previous
short name (`eta`) still works for one release, with a one-line warning naming the option.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from pathlib import Path

import numpy as np

from fitting.data import load_experiments
from fitting.design import (
    CRITERIA,
    NUISANCES,
    design,
    fit_scatter,
    optimize_plan,
    plan_experiments,
    plot_design,
)
from fitting.parameters import (
    parse_parameter_list,
    public_keys,
    public_label,
    public_names,
    resolve_name,
)

from ..io.atomic import save_figure, write_json, write_text
from ..units import counted, parse_quantity
from ..validation import yield_notice
from .setup_options import add_setup_arguments, chain_from_args


def _names(text: str | None) -> tuple[str, ...]:
    return tuple(p.strip() for p in (text or "").split(",") if p.strip())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="*", metavar="FILE",
                        help="trace files or experiment files (.toml) defining the plan "
                        "(else give --velocities ...)")
    nuisances = [public_label(n) for n in NUISANCES]
    parser.add_argument("--params", default="eta_s,mu,C",
                        help="parameters to design for [eta_s,mu,C]; valid: "
                        + ", ".join(n for n in public_names() if n not in nuisances))
    parser.add_argument("--nuisances", default="",
                        help="free nuisances, marginalised: " + ", ".join(nuisances)
                        + " [none: fixed, known from the headers]")
    add_setup_arguments(parser)
    plan = parser.add_argument_group("plan by options (instead of files)")
    plan.add_argument("--velocities", help="impact velocities (m/s), one shot each, e.g. 0.05,0.3")
    plan.add_argument("--contacts", default="", help="recorded contacts, e.g. 6,11")
    plan.add_argument("--sensors", action="store_true",
                      help="also record the embedded sensors of --sensor-beads")
    plan.add_argument("--no-wall", action="store_true", help="do not record the wall force")
    plan.add_argument("--noise-std", default="0.5", help="noise sigma of every channel (N) [0.5]")
    plan.add_argument("--sample-interval", default="1e-6", help="sampling interval (s) [1us]")
    plan.add_argument("--coupling", choices=("dc", "ac"), default="dc",
                      help="ac: piezo sensors, which do not read a static preload [dc]")
    plan.add_argument("--t-end", default="2.5e-3", help="record length after the impact (s) [2.5ms]")
    opt = parser.add_argument_group("optimal plan")
    opt.add_argument("--optimize", type=int, metavar="N",
                     help="recommend the N (velocity, channel) recordings that best determine --params")
    opt.add_argument("--candidate-velocities", default="0.02,0.05,0.1,0.2,0.4,0.8",
                     help="candidate impact velocities (m/s) [0.02,0.05,0.1,0.2,0.4,0.8]")
    opt.add_argument("--candidate-channels",
                     help="candidate channels, e.g. wall,contact_3,contact_10 "
                     "[wall and every third contact]")
    opt.add_argument("--criterion", choices=CRITERIA, default="D",
                     help="D-optimal (log det, default) or A-optimal (sum of squared relative errors)")
    parser.add_argument("--check-fits", type=int, default=0, metavar="SEEDS",
                        help="also fit this many noisy copies and compare the scatter [0: off]")
    parser.add_argument("--out", default="out/design", help="output folder [out/design]")


def _values(chain) -> dict:
    """The values (SI) the design is made at, by public name."""
    setup = chain.setup
    values = {"eta_s": float(setup.eta_s), "mu": float(setup.mu), "mu_star": float(setup.mu_star)}
    if "wall_youngs_pa" in chain.sources:
        values["wall_youngs_pa"] = float(setup.wall_youngs_pa)
    if "wall_poisson" in chain.sources:
        values["wall_poisson"] = float(setup.wall_poisson)
    if float(setup.precompression_n) > 0:
        values["precompression_n"] = float(setup.precompression_n)
    return values


def _csv(result, recommended=None) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    header = ["param", "unit", "value", "stderr", "relative_stderr"]
    if recommended is not None:
        header += ["recommended_stderr", "recommended_relative_stderr"]
    writer.writerow(header)
    for p in result.params:
        row = [public_label(p), result.units[p], repr(result.values[p]), repr(result.stderr[p]),
               repr(result.relative_stderr[p])]
        if recommended is not None:
            row += [repr(recommended.stderr[p]), repr(recommended.relative_stderr[p])]
        writer.writerow(row)
    return buffer.getvalue()


def run(args: argparse.Namespace) -> int:
    # public names, as the library takes them (a previous name has warned here, naming the option)
    params = tuple(map(public_label, parse_parameter_list(args.params, where="--params")))
    nuisances = tuple(dict.fromkeys(public_label(resolve_name(n, where="--nuisances")) for n in _names(args.nuisances)))
    chain = chain_from_args(args)
    setup = chain.setup
    values = _values(chain)
    noise = parse_quantity(args.noise_std, "N", name="--noise-std")
    interval = parse_quantity(args.sample_interval, "s", name="--sample-interval")
    t_end = parse_quantity(args.t_end, "s", name="--t-end")
    out = Path(args.out)
    if args.files and args.velocities:
        raise ValueError("give the plan as trace files or with --velocities, not both.")
    if args.files:
        missing = [f for f in args.files if not Path(f).is_file()]
        if missing:
            raise FileNotFoundError(f"no such trace file: {', '.join(missing)}")
        plan = load_experiments(args.files)
        baseline_units = None
    elif args.velocities:
        velocities = [parse_quantity(v, "m/s", name="--velocities") for v in _names(args.velocities)]
        channels = [f"contact_{int(k)}" for k in _names(args.contacts)]
        if args.sensors:
            channels += [f"sensor_{b}" for b in setup.sensor_beads]
        if not args.no_wall:
            channels.append("wall")
        if not channels:
            raise ValueError("the plan records no channel: give --contacts, --sensors or keep the wall.")
        print(f"simulating the plan: {counted(len(velocities), 'shot')}, channels {', '.join(channels)} ...",
              flush=True)
        notice = yield_notice(setup, velocities, what="the plan's shots")
        if notice:
            print(f"hertzchain design: warning: {notice}", file=sys.stderr)
        plan = plan_experiments(setup, velocities, channels=channels, noise_std_n=noise,
                                sample_interval_s=interval, t_end_s=t_end, coupling=args.coupling)
        baseline_units = [(v, c) for v in velocities for c in channels]
    else:
        raise ValueError("no plan: give trace files, or --velocities (and --contacts, --noise-std, "
                         "--sample-interval, --t-end).")
    print(f"Fisher information of {', '.join(map(public_label, params))} "
          f"({'nuisances fixed' if not nuisances else 'free nuisances: ' + ', '.join(map(public_label, nuisances))}) ...",
          flush=True)
    result = design(plan, params, values=values, nuisances=nuisances)
    data = {**result.to_json(), "values": public_keys(values)}
    recommended = None
    if args.optimize:
        if args.candidate_channels:
            candidates = list(_names(args.candidate_channels))
        else:
            candidates = ["wall"] + [f"contact_{k}" for k in range(1, setup.n_beads, 3)]
        velocities = [parse_quantity(v, "m/s", name="--candidate-velocities")
                      for v in _names(args.candidate_velocities)]
        print(f"optimising a plan of {counted(args.optimize, 'recording')} from {counted(len(velocities), 'velocity', 'velocities')} x "
              f"{counted(len(candidates), 'channel')} ({args.criterion}-optimal) ...", flush=True)
        if args.files:
            first = plan[0]
            base = first.trace.setup()
            noise = float(np.mean(list(first.noise_std_n.values())))
            interval, t_end = float(first.trace.sample_interval_s), float(first.time_s[-1])
        else:
            base = setup
        optimization = optimize_plan(
            base, params, candidate_velocities_m_s=velocities, candidate_channels=candidates,
            size=args.optimize, values=values, nuisances=nuisances, noise_std_n=noise,
            sample_interval_s=interval, t_end_s=t_end, criterion=args.criterion,
            baseline_units=baseline_units, baseline=plan if baseline_units is None else None,
        )
        recommended = optimization.recommended
        given = sum(len(e.channels) for e in plan)
        if args.optimize < given:
            print(f"  note: the recommended plan has {counted(args.optimize, 'recording')}, the given plan "
                  f"{given}; compare plans of the same size (--optimize {given}).")
        data["optimization"] = optimization.to_json()
        chosen = ", ".join(f"{c} at {v:g} m/s" for v, c in optimization.chosen)
        print(f"  recommended: {chosen}")
        notice = yield_notice(base, [v for v, _ in optimization.chosen], what="recommended shots")
        if notice:
            print(f"hertzchain design: warning: {notice}", file=sys.stderr)
    if args.check_fits:
        check = {"given_plan": fit_scatter(plan, params, values=values, nuisances=nuisances,
                                           n_seeds=args.check_fits).to_json()}
        data["check"] = check
    write_json(out / "design.json", data)
    write_text(out / "design.csv", _csv(result, recommended))
    figure = plot_design(recommended or result, baseline=result if recommended else None)
    save_figure(figure, out / "design.png", dpi=120)
    for p in result.params:
        line = (f"  {public_label(p)}: {result.values[p]:.6g} {result.units[p]} ± {result.stderr[p]:.3g} "
                f"({100 * result.relative_stderr[p]:.3g} %)")
        if recommended is not None:
            line += (f" -> recommended plan ± {recommended.stderr[p]:.3g} "
                     f"({100 * recommended.relative_stderr[p]:.3g} %)")
        print(line)
    print(f"wrote {out / 'design.json'}, {out / 'design.csv'}, {out / 'design.png'}")
    return 0
