"""`hertzchain sensitivity`: exact derivatives and elasticities of observables to parameters,
at one setup, over a swept grid of setups, or averaged over a parameter box (global).

Parameters are named by their public names (`hertzchain.parameters`: `eta_s`,
`wall_youngs_pa`, `mu_star`) in the options and in every file and line written; a previous
short name (`eta`, `wall_youngs`) still works for one release, with a one-line warning
naming the option."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from .. import sensitivity as S
from ..io.atomic import save_figure, write_csv, write_json, write_text
from ..io.tracefile import setup_header
from ..parameters import public_name, public_names, resolve_name
from ..units import parse_quantity
from ..validation import check_batch_size
from .setup_options import add_run_arguments, add_setup_arguments, setup_from_args


def _names(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_setup_arguments(parser)
    add_run_arguments(parser)
    group = parser.add_argument_group("sensitivity")
    group.add_argument(
        "--params", type=_names, required=True,
        help="parameters, comma-separated: " + ", ".join(public_names()),
    )
    group.add_argument(
        "--observables", type=_names, required=True,
        help="observables, comma-separated: " + "; ".join(S.OBSERVABLE_FORMS),
    )
    group.add_argument("--mode", choices=("auto", "forward", "reverse"), default="auto",
                       help="AD mode [auto: reverse when fewer observable values than parameters]")
    group.add_argument("--steps-per-contact", type=int, default=200,
                       help="Verlet steps per shortest contact time [200]")
    group.add_argument("--out", default="out/sensitivity", help="output folder [out/sensitivity]")
    group.add_argument("--yes", action="store_true",
                       help="run even when the runs need more memory than is available or more than 1e10 "
                       "bead-steps")
    sweep = parser.add_argument_group("sweep (outer product of the given values)")
    sweep.add_argument("--sweep-velocities", help="impact velocities (m/s), e.g. 0.05,0.1,0.3,1")
    sweep.add_argument("--sweep-wall-youngs", help="wall moduli (Pa), e.g. 3e9,45e9,203e9")
    sweep.add_argument("--sweep", action="append", default=[], metavar="PARAM=V1,V2,...",
                       help="sweep any scalar parameter (SI values or with units, e.g. eta_s=0,1us,2us); "
                            "repeatable")
    sweep.add_argument("--chunk-size", type=int, default=64, help="setups per vmapped call [64]")
    glob = parser.add_argument_group("global (derivative-based measures over a box)")
    glob.add_argument("--box", action="append", default=[], metavar="PARAM=LOW:HIGH",
                      help="range of a parameter (SI or with units, e.g. eta_s=0:2us); repeatable; turns "
                           "on the global study")
    glob.add_argument("--global-samples", type=int, default=64, help="Latin-hypercube points [64]")
    glob.add_argument("--seed", type=int, default=0, help="sampling seed [0]")


def _values(text: str, unit: str, option: str) -> list[float]:
    return [parse_quantity(part, unit, name=option) for part in text.split(",") if part.strip()]


def _sweep_axes(args) -> dict[str, list[float]]:
    """Swept parameter (public name, as the library takes it) -> values (SI)."""
    axes = {}
    if args.sweep_velocities:
        axes["striker_velocity_m_s"] = _values(args.sweep_velocities, "m/s", "--sweep-velocities")
    if args.sweep_wall_youngs:
        axes["wall_youngs_pa"] = _values(args.sweep_wall_youngs, "Pa", "--sweep-wall-youngs")
    for item in args.sweep:
        written, _, values = item.partition("=")
        if not values:
            raise ValueError(f"--sweep {item!r}: expected PARAM=V1,V2,... (SI values).")
        key = resolve_name(written.strip(), where="--sweep")
        if public_name(key) in axes:
            raise ValueError(f"--sweep: {public_name(key)} is swept twice.")
        axes[public_name(key)] = _values(values, S.PARAMETERS[key].unit, f"--sweep {written.strip()}")
    return axes


def _box(args) -> dict[str, tuple[float, float]]:
    """Parameter (public name, as the library takes it) -> (low, high) of the global study's
    box (SI)."""
    box = {}
    for item in args.box:
        written, _, bounds = item.partition("=")
        low, colon, high = bounds.partition(":")
        if not colon:
            raise ValueError(f"--box {item!r}: expected PARAM=LOW:HIGH (SI, or with units: "
                             "wall_youngs_pa=3GPa:203GPa).")
        key = resolve_name(written.strip(), where="--box")
        if public_name(key) in box:
            raise ValueError(f"--box: {public_name(key)} is given twice.")
        unit, option = S.PARAMETERS[key].unit, f"--box {written.strip()}"
        box[public_name(key)] = (parse_quantity(low, unit, name=option), parse_quantity(high, unit, name=option))
    return box


def _write_rows(path, rows: list[dict]) -> None:
    """`rows` (dicts with the same keys, in the same order) as a CSV table with a header of
    their keys; an empty file when there are none."""
    if not rows:
        write_text(path, "")
        return
    write_csv(path, list(rows[0]), (row.values() for row in rows))


def _write_trace_csv(path, result: S.SensitivityResult) -> None:
    columns = {"time_s": result.time_s}
    for o in result.trace_observables:
        columns[o] = result.values[o]
        for p in result.params:
            d = np.asarray(result.derivative[o][p])
            if d.ndim == 1:
                columns[f"d({o})/d({p})"] = d
            else:
                for i in range(d.shape[1]):
                    columns[f"d({o})/d({p}[{i + 1}])"] = d[:, i]
    table = np.column_stack(list(columns.values()))
    write_csv(path, list(columns), ([f"{x:.10g}" for x in row] for row in table.tolist()))


def _run_options(args) -> dict:
    return {
        "t_end_s": parse_quantity(args.t_end, "s", name="--t-end"),
        "sample_interval_s": parse_quantity(args.sample_interval, "s", name="--sample-interval"),
        "dt_s": None if args.dt is None else parse_quantity(args.dt, "s", name="--dt"),
    }


def run(args: argparse.Namespace) -> int:
    setup = setup_from_args(args)
    options = _run_options(args)
    out = Path(args.out)
    params = tuple(public_name(resolve_name(name, where="--params")) for name in args.params)
    axes, box = _sweep_axes(args), _box(args)
    if axes and box:
        raise ValueError("give either sweep options or --box (a global study), not both.")
    if not args.yes:
        # every run records the chain's contacts with one tangent per parameter (forward mode)
        n_runs = args.global_samples if box else math.prod(len(v) for v in axes.values()) if axes else 1
        check_batch_size(setup, n_runs=n_runs, n_runs_in_memory=args.chunk_size,
                         n_channels=(1 + len(params)) * (setup.n_beads + 2), **options)
    header = {"setup": setup_header(setup)}
    if box:
        print(f"global sensitivity over {', '.join(map(public_name, box))} ({args.global_samples} samples) ...",
              flush=True)
        result = S.global_sensitivity(
            setup, args.observables, box, params=params, n_samples=args.global_samples,
            seed=args.seed, chunk_size=args.chunk_size, **options,
        )
        write_json(out / "sensitivity.json", {**header, "global": result.to_json(),
                                              **result.samples.to_json()})
        _write_rows(out / "sensitivity.csv", result.samples.rows())
        save_figure(S.plot_global_ranking(result), out / "global_ranking.png", dpi=120)
        for o, order in result.ranking.items():
            ranked = ", ".join(f"{p} {result.mean_squared_elasticity[o][p]:.3g}" for p in order)
            print(f"  {o}: {ranked}")
        print(f"wrote {out / 'sensitivity.json'}, {out / 'sensitivity.csv'}, {out / 'global_ranking.png'}")
        return 0
    if axes:
        print(f"sensitivity sweep over {' x '.join(f'{public_name(k)} ({len(v)})' for k, v in axes.items())} ...",
              flush=True)
        result = S.sensitivity_sweep(
            setup, params, args.observables, axes, mode=args.mode,
            steps_per_contact=args.steps_per_contact, chunk_size=args.chunk_size, **options,
        )
        for message in result.messages.values():
            print(f"  note: {message}")
        figure_name = "sweep.png"
        save_figure(S.plot_sweep(result), out / figure_name, dpi=110)
    else:
        result = S.sensitivity(setup, params, args.observables, mode=args.mode,
                               steps_per_contact=args.steps_per_contact, **options)
        figure_name = "elasticities.png"
        save_figure(S.plot_elasticities(result), out / figure_name, dpi=120)
        if result.trace_observables:
            _write_trace_csv(out / "trace_sensitivity.csv", result)
            save_figure(S.plot_trace_sensitivities(result), out / "trace_sensitivity.png", dpi=110)
        for o in result.observables:
            if o in result.trace_observables:
                continue
            parts = ", ".join(
                f"{p} {float(np.ravel(result.elasticity[o][p])[0]):+.4g}"
                + (" (per bead: see CSV)" if np.size(result.elasticity[o][p]) > 1 else "")
                for p in result.params
            )
            print(f"  {o} = {float(result.values[o]):.6g} {result.units[o]}; elasticities: {parts}")
    write_json(out / "sensitivity.json", {**header, **result.to_json()})
    _write_rows(out / "sensitivity.csv", result.rows())
    print(f"wrote {out / 'sensitivity.json'}, {out / 'sensitivity.csv'}, {out / figure_name}"
          f" ({result.mode} mode)")
    return 0
