"""Command-line options that describe a chain, shared by every command that builds one."""

from __future__ import annotations

import argparse

from ..chain import PLASTIC_LAWS, ChainSetup
from ..materials import material
from ..units import parse_quantity
from ..validation import check_plausible

# (option, ChainSetup field, unit, help)
_QUANTITIES = (
    ("--bead-radius", "bead_radius_m", "m", "bead radius (m; e.g. 13mm) [0.013]"),
    ("--bead-density", "bead_density_kg_m3", "kg/m3", "bead density (kg/m^3) [7780]"),
    ("--bead-youngs", "bead_youngs_pa", "Pa", "bead Young's modulus (Pa; e.g. 203GPa) [2.03e11]"),
    ("--bead-poisson", "bead_poisson", "", "bead Poisson ratio [0.3]"),
    ("--bead-yield-stress", "bead_yield_stress_pa", "Pa", "bead yield stress (Pa) [2e9]"),
    ("--striker-radius", "striker_radius_m", "m", "striker radius (m) [bead radius]"),
    ("--striker-mass", "striker_mass_kg", "kg", "striker mass (kg), instead of its radius"),
    ("--striker-velocity", "striker_velocity_m_s", "m/s", "impact velocity (m/s) [0.3]"),
    ("--wall-youngs", "wall_youngs_pa", "Pa", "wall Young's modulus (Pa; inf = rigid) [bead's]"),
    ("--wall-poisson", "wall_poisson", "", "wall Poisson ratio [bead's]"),
    ("--eta", "eta_s", "s", "viscoelastic time eta (s; e.g. 2us) [0]"),
    ("--dashpot", "dashpot_n_s_m", "Ns/m", "linear dashpot of every contact in compression (N s/m) [0]"),
    ("--contact-exponent", "contact_exponent", "",
     "exponent n of every contact's law F = kappa d_r^1.5 (d/d_r)^n, equal to Hertz's at d_r = 10 um [1.5: Hertz]"),
    ("--mu", "mu", "", "track friction coefficient [0]"),
    ("--mu-star", "mu_star", "", "thwarted-rotation friction, kappa* = (1+mu*) kappa [0]"),
    ("--precompression", "precompression_n", "N", "static preload (N) [0]"),
    ("--sensor-beta", "sensor_beta", "", "embedded sensor mass ratio beta [0.11]"),
    ("--sensor-f0", "sensor_f0_hz", "Hz", "embedded sensor resonance (Hz; e.g. 85kHz) [85e3]"),
)


def _int_list(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from error


def add_setup_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the chain-description options (SI numbers; unit suffixes such as 13mm accepted)."""
    group = parser.add_argument_group("chain setup (SI units; suffixes like 13mm, 5GPa, 2us accepted)")
    group.add_argument("--n-beads", type=int, default=21, help="number of beads N [21]")
    group.add_argument("--wall-material", help="wall material by name (e.g. Cu, plexiglass, W)")
    group.add_argument("--end", choices=("wall", "free"), default="wall", help="far end [wall]")
    group.add_argument(
        "--sensor-beads", type=_int_list, default=(), help="beads with an embedded sensor, e.g. 6,14"
    )
    for option, _, _, help_text in _QUANTITIES:
        group.add_argument(option, help=help_text)
    group.add_argument("--plasticity", choices=PLASTIC_LAWS,
                       help="elastic-plastic contacts beyond the yield force of --bead-yield-stress, by "
                            "Thornton's law or Jackson & Green's (measured contacts) [off: Hertz]")


def setup_from_args(args: argparse.Namespace) -> ChainSetup:
    """Build the `ChainSetup` the options describe; errors name the option."""
    values = {}
    for option, field, unit, _ in _QUANTITIES:
        text = getattr(args, option.lstrip("-").replace("-", "_"))
        if text is not None:
            values[field] = parse_quantity(text, unit, name=option)
            check_plausible(field, values[field], where=option)
    if args.wall_material:
        if "wall_youngs_pa" in values:
            raise ValueError("Give --wall-material or --wall-youngs, not both.")
        wall = material(args.wall_material)
        values["wall_youngs_pa"] = wall.youngs_pa
        values.setdefault("wall_poisson", wall.poisson)
    if args.plasticity:
        values.update(plasticity=True, plastic_law=args.plasticity)
    return ChainSetup(args.n_beads, end=args.end, sensor_beads=args.sensor_beads, **values)


def add_run_arguments(parser: argparse.ArgumentParser, *, t_end_s: float = 2.5e-3) -> None:
    """Add the run options: duration, sampling, time step, recorded contacts."""
    group = parser.add_argument_group("run")
    group.add_argument("--t-end", default=str(t_end_s), help=f"recorded duration (s) [{t_end_s:g}]")
    group.add_argument("--sample-interval", default="1e-6", help="sampling interval (s) [1e-6]")
    group.add_argument("--dt", help="time step (s) [chosen to resolve the shortest contact]")
    group.add_argument(
        "--contacts",
        type=_int_list,
        default=None,
        help="contacts to record, e.g. 6,11 (contact K between bead K and K+1; 0 = striker's; "
        "the wall is always recorded) [6,11 for 21 beads: 0.3 N and 0.53 N]",
    )


def run_options(args: argparse.Namespace, n_beads: int) -> dict:
    """Keyword arguments of `simulate` from the run options."""
    contacts = args.contacts
    if contacts is None:
        contacts = tuple(sorted({min(max(round(f * n_beads), 0), n_beads - 1) for f in (0.3, 0.53)}))
    return {
        "t_end_s": parse_quantity(args.t_end, "s", name="--t-end"),
        "sample_interval_s": parse_quantity(args.sample_interval, "s", name="--sample-interval"),
        "dt_s": None if args.dt is None else parse_quantity(args.dt, "s", name="--dt"),
        "contacts": contacts,
    }
