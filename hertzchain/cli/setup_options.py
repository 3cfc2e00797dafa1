"""Command-line options that describe a chain, shared by every command that builds one.

Each value of the chain comes from the first of: an option giving it (`--bead-youngs
110GPa`), a material named by an option (`--bead-material brass`), the `[chain]` table of a
setup file (`--config setup.toml`: the keys and units of an experiment file, see
`hertzchain.io.importer`), `ChainSetup`'s default (the paper's chain). `chain_from_args`
returns the setup and where each value came from.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from .. import laws
from ..chain import DEPRECATED_LAW_KEYWORDS, PLASTIC_LAWS, ChainSetup
from ..io.importer import load_chain
from ..io.tracefile import REDUNDANT_TOLERANCE
from ..materials import BEAD_STEEL, Material, material, sphere_mass_kg
from ..sweep import default_contacts
from ..units import format_si, parse_field, parse_quantity
from ..validation import check_plausible

# (option, ChainSetup field, help); the value's unit is the one the field's name carries.
_QUANTITIES = (
    ("--bead-radius", "bead_radius_m", "bead radius (m; e.g. 13mm) [0.013]"),
    ("--bead-density", "bead_density_kg_m3", "bead density (kg/m^3) [7780]"),
    ("--bead-youngs", "bead_youngs_pa", "bead Young's modulus (Pa; e.g. 203GPa) [2.03e11]"),
    ("--bead-poisson", "bead_poisson", "bead Poisson ratio [0.3]"),
    ("--bead-yield-stress", "bead_yield_stress_pa", "bead yield stress (Pa; e.g. 2GPa) [2e9]"),
    ("--striker-radius", "striker_radius_m", "striker radius (m) [bead radius]"),
    ("--striker-mass", "striker_mass_kg",
     "striker mass (kg); with --striker-radius only if the two agree with the striker's density"),
    ("--striker-density", "striker_density_kg_m3", "striker density (kg/m^3) [bead's]"),
    ("--striker-youngs", "striker_youngs_pa", "striker Young's modulus (Pa) [bead's]"),
    ("--striker-poisson", "striker_poisson", "striker Poisson ratio [bead's]"),
    ("--striker-velocity", "striker_velocity_m_s", "impact velocity (m/s) [0.3]"),
    ("--wall-youngs", "wall_youngs_pa", "wall Young's modulus (Pa; e.g. 5GPa; inf = rigid) [bead's]"),
    ("--wall-poisson", "wall_poisson", "wall Poisson ratio [bead's]"),
    ("--eta", "eta_s", "viscoelastic time eta (s; e.g. 2us) [0: lossless]"),
    ("--dashpot", "dashpot_n_s_m", "linear dashpot of every contact in compression (N s/m) [0]"),
    ("--contact-exponent", "contact_exponent",
     "exponent n of every contact's law F = kappa d_r^1.5 (d/d_r)^n, equal to Hertz's at d_r = 10 um [1.5: Hertz]"),
    ("--mu", "mu", "track friction coefficient [0]"),
    ("--mu-star", "mu_star", "thwarted-rotation friction, kappa* = (1+mu*) kappa [0]"),
    ("--precompression", "precompression_n", "static preload (N) [0]"),
    ("--sensor-beta", "sensor_beta", "embedded sensor mass ratio beta [0.11]"),
    ("--sensor-f0", "sensor_f0_hz", "embedded sensor resonance (Hz; e.g. 85kHz) [85e3]"),
)
_OPTION_OF = {field: option for option, field, _ in _QUANTITIES}

# The ChainSetup fields a material gives each body: Material attribute -> field.
_MATERIAL_FIELDS = {
    "bead": {"youngs_pa": "bead_youngs_pa", "poisson": "bead_poisson",
             "density_kg_m3": "bead_density_kg_m3", "yield_stress_pa": "bead_yield_stress_pa"},
    "striker": {"youngs_pa": "striker_youngs_pa", "poisson": "striker_poisson",
                "density_kg_m3": "striker_density_kg_m3"},
    "wall": {"youngs_pa": "wall_youngs_pa", "poisson": "wall_poisson"},
}


@dataclasses.dataclass(frozen=True)
class ChainChoice:
    """A chain described on the command line.

    **Arguments:**

    - `setup`: the `ChainSetup`.
    - `sources`: field -> where its value came from (`"--bead-radius"`, `"--bead-material
      brass"`, the setup file's path); fields left at `ChainSetup`'s default are absent.
    - `materials`: body (`"bead"`, `"striker"`, `"wall"`) -> the material named for it.
    """

    setup: ChainSetup
    sources: dict
    materials: dict

    def describe(self, swept=()) -> list[str]:
        """Console lines: the bodies' materials and the values each source gave (`swept`:
        fields a sweep's grid sets instead)."""
        setup = self.setup

        def value(field, text):
            return "swept (--grid)" if field in swept else text

        striker_size = ("striker_radius_m" in swept or "striker_mass_kg" in swept)
        bodies = {
            "beads": ("bead", f"{setup.n_beads} of radius "
                              + value("bead_radius_m", format_si(float(setup.bead_radius_m[0]), "m"))),
            "striker": ("striker", "size swept (--grid)" if striker_size else
                        f"radius {format_si(float(setup.striker_radius_m), 'm')}, "
                        f"mass {float(setup.striker_mass_kg) * 1e3:.4g} g"),
        }
        lines = []
        for label, (body, size) in bodies.items():
            name = self.materials.get(body, "")
            youngs = float(getattr(setup, f"{body}_youngs_pa").ravel()[0])
            youngs = value(f"{body}_youngs_pa", format_si(youngs, "Pa"))
            density = value(f"{body}_density_kg_m3",
                            f"{float(getattr(setup, f'{body}_density_kg_m3').ravel()[0]):.4g} kg/m^3")
            lines.append(f"  {label}: {name + ', ' if name else ''}{size}, Y = {youngs}, rho = {density}")
        if setup.end == "wall":
            wall = self.materials.get("wall", "")
            youngs = value("wall_youngs_pa", format_si(float(setup.wall_youngs_pa), "Pa"))
            lines.append(f"  wall: {wall + ', ' if wall else ''}Y = {youngs}")
        by_source: dict[str, list[str]] = {}
        for field, source in self.sources.items():
            if field not in swept:
                by_source.setdefault(source, []).append(field)
        for source, fields in by_source.items():
            lines.append(f"  from {source}: {', '.join(fields)}")
        return lines


def option_of_field(field: str) -> str | None:
    """The option that sets a `ChainSetup` field (`"eta_s"` -> `"--eta"`), None if none does."""
    return _OPTION_OF.get(field)


def _int_list(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from error


def add_setup_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the chain-description options (SI numbers; unit suffixes such as 13mm accepted)."""
    group = parser.add_argument_group(
        "chain setup", "SI units; suffixes like 13mm, 5GPa, 2us, 8.9g accepted. Default: the paper's "
        "chain, 21 steel beads of radius 13 mm, a striker like them, a steel wall, lossless contacts. "
        "A value comes from its option, else from a --*-material, else from --config, else the default.")
    group.add_argument("--config", metavar="SETUP.TOML",
                       help="the chain from the [chain] table of a TOML file (the keys and units of an "
                            "experiment file, e.g. bead_radius_m = \"13mm\"); options given here override it")
    group.add_argument("--n-beads", type=int, help="number of beads N [21]")
    for body, example in (("bead", "brass"), ("striker", "steel"), ("wall", "Cu")):
        group.add_argument(f"--{body}-material", metavar="NAME",
                           help=f"{body} material by name (e.g. {example}; an unknown name lists the known "
                                f"ones); the {body} options below override its values")
    group.add_argument("--end", choices=("wall", "free"), help="far end [wall]")
    group.add_argument(
        "--sensor-beads", type=_int_list, default=(), help="beads with an embedded sensor, e.g. 6,14"
    )
    for option, _, help_text in _QUANTITIES:
        group.add_argument(option, help=help_text)
    group.add_argument("--plasticity", choices=PLASTIC_LAWS,
                       help="elastic-plastic contacts beyond the yield force of --bead-yield-stress, by "
                            "Thornton's law or Jackson & Green's (measured contacts) [off: Hertz]")


def _material_values(body: str, found: Material, option: str, density_given: bool) -> dict:
    values = {}
    for attribute, field in _MATERIAL_FIELDS[body].items():
        value = getattr(found, attribute)
        if value is None and attribute == "density_kg_m3":
            if not density_given:
                raise ValueError(f"{option} {found.name}: the catalogue has no density for it (a wall "
                                 f"sample); give --{body}-density too, or another material.")
            continue
        values[field] = value  # a yield stress of None: unknown, no yield check
    return values


def _file_values(path: str) -> dict:
    """The setup file's chain as ChainSetup keywords (a bead mass becomes a density)."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"--config {path}: no such file.")
    values = {k: v for k, v in load_chain(path).items() if not k.startswith("x_")}
    if "bead_mass_kg" in values:
        mass = values.pop("bead_mass_kg")
        density = mass / sphere_mass_kg(values.get("bead_radius_m", 0.013), 1.0)
        given = values.setdefault("bead_density_kg_m3", density)
        if abs(given - density) > REDUNDANT_TOLERANCE * density:
            raise ValueError(f"{path} [chain]: bead_mass_kg = {mass:.6g} implies a density of "
                             f"{density:.6g} kg/m^3, bead_density_kg_m3 = {given:.6g}: correct one of "
                             "them or give only one.")
    return values


def _striker_size(values: dict, sources: dict) -> None:
    """Keep the striker's radius where its mass is given too, if the two agree."""
    if "striker_mass_kg" not in values or "striker_radius_m" not in values:
        return
    mass, radius = values["striker_mass_kg"], values["striker_radius_m"]
    density = values.get("striker_density_kg_m3", values.get("bead_density_kg_m3", BEAD_STEEL.density_kg_m3))
    implied = sphere_mass_kg(radius, density)
    if abs(mass - implied) > REDUNDANT_TOLERANCE * implied:
        where = sources.get("striker_density_kg_m3", sources.get("bead_density_kg_m3", "the default"))
        raise ValueError(
            f"striker mass {mass:.4g} kg ({sources['striker_mass_kg']}) and radius {radius:.4g} m "
            f"({sources['striker_radius_m']}) disagree: a sphere of that radius and density {density:.6g} "
            f"kg/m^3 ({where}) weighs {implied:.4g} kg ({100 * (mass / implied - 1):+.3g} %); give one of "
            "them, or correct the other or the density."
        )
    del values["striker_mass_kg"]
    del sources["striker_mass_kg"]


def chain_from_args(args: argparse.Namespace) -> ChainChoice:
    """The chain the options describe; errors name the option."""
    values: dict = {}
    sources: dict = {}

    def take(new: dict, source: str) -> None:
        values.update(new)
        sources.update(dict.fromkeys(new, source))

    if args.config:
        take(_file_values(args.config), args.config)
    materials = {}
    for body in _MATERIAL_FIELDS:
        name = getattr(args, f"{body}_material")
        if name:
            option = f"--{body}-material"
            try:
                found = material(name)
            except ValueError as error:
                raise ValueError(f"{option}: {error}") from None
            materials[body] = found.name
            density_given = getattr(args, f"{body}_density", None) is not None
            take(_material_values(body, found, option, density_given), f"{option} {name}")
    options = {}
    for option, field, _ in _QUANTITIES:
        text = getattr(args, option.lstrip("-").replace("-", "_"))
        if text is not None:
            options[field] = parse_field(field, text, where=option)
            check_plausible(field, options[field], where=option)
            take({field: options[field]}, option)
    if "striker_mass_kg" in options and "striker_radius_m" not in options:
        sources.pop("striker_radius_m", None)  # a mass on the command line replaces the file's radius
        values.pop("striker_radius_m", None)
    elif "striker_radius_m" in options and "striker_mass_kg" not in options:
        sources.pop("striker_mass_kg", None)
        values.pop("striker_mass_kg", None)
    _striker_size(values, sources)
    if args.n_beads is not None:
        take({"n_beads": args.n_beads}, "--n-beads")
    if args.end is not None:
        take({"end": args.end}, "--end")
    if args.plasticity:
        take({"plasticity": True, "plastic_law": args.plasticity}, "--plasticity")
    n_beads = values.pop("n_beads", 21)
    # the law's keyword spelling (options and setup files) becomes its law object
    spelled = {name: values.pop(name) for name in DEPRECATED_LAW_KEYWORDS if name in values}
    if spelled:
        try:
            values["contact_law"] = laws.contact_law_from_keywords(**spelled)
        except ValueError as error:
            raise ValueError(f"{', '.join(sorted({sources[name] for name in spelled}))}: {error}") from None
    setup = ChainSetup(n_beads, sensor_beads=args.sensor_beads, **values)
    return ChainChoice(setup, sources, materials)


def setup_from_args(args: argparse.Namespace) -> ChainSetup:
    """Build the `ChainSetup` the options describe; errors name the option."""
    return chain_from_args(args).setup


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
        "the wall is always recorded) [the contacts at 0.3 and 0.53 of the chain's length: "
        "6,11 for 21 beads]",
    )


def run_options(args: argparse.Namespace, n_beads: int) -> dict:
    """Keyword arguments of `simulate` from the run options."""
    return {
        "t_end_s": parse_quantity(args.t_end, "s", name="--t-end"),
        "sample_interval_s": parse_quantity(args.sample_interval, "s", name="--sample-interval"),
        "dt_s": None if args.dt is None else parse_quantity(args.dt, "s", name="--dt"),
        "contacts": default_contacts(n_beads) if args.contacts is None else args.contacts,
    }
