"""`hertzchain contact`: drive the elastic-plastic contact law along measured force-approach
curves, report it at the given constants and calibrate its yield stress per material.

    hertzchain contact force10.mat force15.mat s302_10.mat --material steel_440C \\
        --material steel_440C --material steel_302 --radius 3.175e-3 --out out/contact

Each file is read as it is (`.mat` with `Fexternal` [s, m, N] or `fdK` [m, N]; CSV with
`approach_m`, `force_n`, optionally `time_s`). `--material` is given once (all files) or
once per file, a materials-table name; `--youngs`, `--poisson`, `--yield-stress`,
`--rate-constant` replace its constants (or stand for it). Writes `contact.json`, one
`<stem>.csv` per file, `contact.png` and `residuals.png` into `--out`, written as a whole (the
previous run's folder is replaced; `hertzchain.io.atomic.output_folder`).

By default the law is rate-independent apart from its dynamic yield stress, with the
hardness of its fully plastic branch at 2.84 sigma_Y; `--fit-rate-constant` and
`--fit-hardness-ratio` fit the rate constant and that ratio per material with sigma_Y. `--damping` adds
a Kuwabara-Kono damping force with one damping time per material, fitted with sigma_Y (on
Burgoyne & Daraio's curves it follows the force's lead over the approach and their
unloading: `benchmarks/results/contact_burgoyne/rate_terms.md`); `--time-shift` fits a time
alignment of the force and approach records per curve instead (a processing nuisance,
bounded by `--max-shift`), reported per curve with its sigma; `--approach-drift` fits a
linear drift of each curve's approach record (m/s; the approach of a bar test is the
difference of two integrated gauge records, which a gain mismatch or a baseline error makes
drift), reported per curve with its sigma.

Exits 3 (as `hertzchain fit` on an unconverged fit) when a material's joint fit or a
per-curve fit, whose scatter is one of the yield stress's reported errors, reached no
optimum; `contact.json` names them (`unconverged_fits`, `yield_stress_per_curve_converged`).

Compiled programs are kept in JAX's persistent compilation cache (`fitting.compilation_cache`),
so that a second calibration of records of the same lengths skips compiling;
`--no-compile-cache` turns it off.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys

from fitting.compilation_cache import enable_compilation_cache
from fitting.contact_calibration import (
    GEOMETRIES,
    MAX_TIME_SHIFT_S,
    OFFSETS,
    ContactGeometry,
    calibrate,
    read_curve,
    write_outputs,
)

from ..io.atomic import output_folder
from ..materials import Material, material
from ..units import counted, parse_quantity
from .errors import EXIT_NOT_CONVERGED, exit_codes_epilog
from .shared_options import add_compile_cache_option


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = exit_codes_epilog("a material's joint fit or a per-curve fit of its yield stress "
                                      "reached no optimum")
    parser.add_argument("files", nargs="+", help="force-approach files (.mat Fexternal/fdK, .csv)")
    parser.add_argument("--material", action="append", default=[],
                        help="materials-table name, once for all files or once per file")
    parser.add_argument("--youngs", help="Young's modulus (Pa, or with a unit: 200GPa)")
    parser.add_argument("--poisson", type=float, help="Poisson ratio")
    parser.add_argument("--yield-stress", help="quasi-static yield stress (Pa, or 600MPa)")
    parser.add_argument("--rate-constant", type=float,
                        help="C of sigma_Y (1 + C ln(strain rate / 1e-3 /s)); 0: no rate hardening")
    parser.add_argument("--geometry", choices=GEOMETRIES, default="sphere-sphere",
                        help="two spheres or a sphere on a flat of the same material [sphere-sphere]")
    parser.add_argument("--radius", required=True, help="sphere radius (m, or 3.175mm)")
    parser.add_argument("--radius-b", help="second sphere's radius (m) if it differs")
    parser.add_argument("--offset", choices=OFFSETS, default="first-sample",
                        help="approach offset: subtract the first sample's [first-sample] or keep it (none)")
    parser.add_argument("--strain-rate", type=float,
                        help="strain rate (1/s) for files without a time column (rate hardening needs one)")
    parser.add_argument("--fit-rate-constant", action="store_true", help="fit the rate constant as well")
    parser.add_argument("--fit-hardness-ratio", action="store_true",
                        help="fit the hardness ratio H/sigma_Y of the law's fully plastic branch as well [2.84]")
    parser.add_argument("--damping", action="store_true",
                        help="fit a Kuwabara-Kono damping time per material on top of the law [off]")
    parser.add_argument("--time-shift", action="store_true",
                        help="fit a time shift of the approach against the force per curve [off]")
    parser.add_argument("--approach-drift", action="store_true",
                        help="fit a linear drift (m/s) of each curve's approach record [off]")
    parser.add_argument("--max-shift", default=f"{MAX_TIME_SHIFT_S * 1e6:g}us",
                        help=f"bound of --time-shift (s, or 13us) [{MAX_TIME_SHIFT_S * 1e6:g}us]")
    add_compile_cache_option(parser)
    parser.add_argument("--out", default="out/contact", help="output folder [out/contact]")


# A sphere's radius above this many metres is taken as a value written without its unit.
MAX_RADIUS_M = 1.0


def _length(text, name):
    """A sphere's radius, m: positive, and below `MAX_RADIUS_M` (a bare number is in m)."""
    try:
        value = parse_quantity(text, "m")
    except ValueError as error:
        raise ValueError(f"--{name}: {error}") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"--{name} {text}: a radius must be positive, e.g. --{name} 3.175mm.")
    if value >= MAX_RADIUS_M:
        raise ValueError(f"--{name} {text}: {value:g} m is not a sphere's radius (a bare number is in m); "
                         f"did you mean {text.strip()}mm?")
    return value


def _materials(args) -> list[Material]:
    names = args.material
    if len(names) not in (0, 1, len(args.files)):
        raise ValueError(f"--material given {len(names)} times for {len(args.files)} files: give it once "
                         "(all files) or once per file.")
    overrides = {}
    if args.youngs is not None:
        overrides["youngs_pa"] = parse_quantity(args.youngs, "Pa")
    if args.poisson is not None:
        overrides["poisson"] = args.poisson
    if args.yield_stress is not None:
        overrides["yield_stress_pa"] = parse_quantity(args.yield_stress, "Pa")
    if args.rate_constant is not None:
        overrides["yield_rate_constant"] = args.rate_constant
    if not names:
        missing = [f"--{k}" for k, key in (("youngs", "youngs_pa"), ("poisson", "poisson"),
                                          ("yield-stress", "yield_stress_pa")) if key not in overrides]
        if missing:
            raise ValueError(f"no --material: give {', '.join(missing)} (or a materials-table name with --material).")
        return [Material(name="given", **overrides)] * len(args.files)
    chosen = [material(n) for n in names]
    chosen = [dataclasses.replace(m, **overrides) for m in chosen]
    return chosen * len(args.files) if len(chosen) == 1 else chosen


def run(args: argparse.Namespace) -> int:
    enable_compilation_cache(not args.no_compile_cache)
    geometry = ContactGeometry(args.geometry, _length(args.radius, "radius"),
                               None if args.radius_b is None else _length(args.radius_b, "radius-b"))
    curves = [read_curve(path, m) for path, m in zip(args.files, _materials(args))]
    names = [c.name for c in curves]
    if len(set(names)) != len(names):
        raise ValueError("two input files have the same stem; their <stem>.csv outputs would collide: rename one.")
    try:
        max_shift_s = parse_quantity(args.max_shift, "s")
    except ValueError as error:
        raise ValueError(f"--max-shift: {error}") from None
    with output_folder(args.out, "contact", "contact.json") as out:
        report = calibrate(curves, geometry, offset=args.offset, fit_rate_constant=args.fit_rate_constant,
                           fit_damping=args.damping, fit_time_shift=args.time_shift,
                           fit_hardness_ratio=args.fit_hardness_ratio, fit_approach_drift=args.approach_drift,
                           max_shift_s=max_shift_s,
                           strain_rate_s_given=args.strain_rate,
                           progress=lambda text: print(text, file=sys.stderr, flush=True))
        data = write_outputs(report, curves, out)
    for name, entry in data["materials"].items():
        fitted, given, errors = entry["fitted"], entry["given"], entry["stderr"]
        print(f"{name}: sigma_Y fitted {fitted['yield_stress_pa'] / 1e6:.0f} +- {errors['yield_stress_pa'] / 1e6:.0f} MPa "
              f"(given {given['yield_stress_pa'] / 1e6:.0f} MPa), rate constant {fitted['rate_constant']:.4g}"
              + (f", damping time {fitted['eta_s'] * 1e6:.3g} us" if args.damping else "")
              + (f", hardness ratio {fitted['hardness_ratio']:.3g} +- {errors['hardness_ratio']:.2g}"
                 if args.fit_hardness_ratio else "")
              + ("" if entry["converged"] else " (NOT CONVERGED)"))
    for entry in data["curves"]:
        print(f"  {entry['file']}: peak force {entry['peak_force_measured_n'] / 1e3:.3g} kN, error at given "
              f"constants {100 * entry['peak_force_error_model']:+.1f} %, RMS/peak fitted "
              f"{100 * entry['rms_over_peak_fitted']:.1f} %"
              + (f", time shift {entry['time_shift_s'] * 1e6:+.2f} us "
                 + (f"+- {entry['time_shift_stderr_s'] * 1e6:.2f} us" if entry['time_shift_stderr_s'] is not None
                    else "(at its bound)") if args.time_shift else "")
              + (f", approach drift {entry['approach_drift_m_s']:+.3f}"
                 + (f" +- {entry['approach_drift_stderr_m_s']:.3f}" if entry['approach_drift_stderr_m_s'] is not None
                    else "") + " m/s" if args.approach_drift else ""))
    print(f"wrote contact.json, contact.png, residuals.png and {counted(len(curves), 'CSV file')} to {args.out}")
    unconverged = [f"{name}: {', '.join(entry['unconverged_fits'])}" for name, entry in data["materials"].items()
                   if not entry["converged"]]
    if unconverged:
        print(f"hertzchain contact: error: no optimum reached by {'; '.join(unconverged)} (their values and "
              "errors are the last iterate's).", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0
