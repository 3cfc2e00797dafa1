"""Named physical parameters of a `ChainSetup`: what each name reads and sets.

One registry, `PARAMETERS`, maps a short name (`eta`, `wall_youngs`, `bead_radius`, ...) to
a `Parameter` that reads the value from a setup and writes a new value into it, in SI
units. The short names are the registry's keys, what code uses; a user writes and reads
each parameter by its public name (`Parameter.public_name`), the unit-suffixed spelling of
the `ChainSetup` field it sets (`eta_s`, `wall_youngs_pa`, `bead_yield_stress_pa`), or of
the quantity where no field holds it (`striker_mass_kg`, `yield_force_n`, `bead_masses_kg`);
dimensionless ones keep theirs (`mu`, `mu_star`, `wall_poisson`, `bead_poisson`,
`sensor_beta`). `resolve_name` maps either spelling to the key; the short one, the previous
public name, warns once, one line (`ParameterNameWarning`), naming the name to write. Every
function that takes parameter names from its caller resolves them so; code holding keys
looks them up in `PARAMETERS` (`key_values`, `with_keys`) and hands public names to those
functions, so only a user's spelling warns. `public_name` maps a key or a per-bead label
(`bead_masses[3]`) to what a user sees. `get` and `set` are
pure and differentiable, so a value can be traced through `jax.grad`, `jax.jacfwd` and
`jax.vmap`. `hertzchain.sensitivity` takes derivatives
against these names. What a name does to a setup is defined here and nowhere else: a
registry that fits setup quantities (`fitting.parameters`, which adds bounds, coordinate
transforms and scopes) uses these entries' `get` and `set` for the names it shares.

**Parameters** (public name, key; SI units): `eta_s` (`eta`), `mu`, `mu_star`,
`striker_velocity_m_s` (`striker_velocity`), `striker_mass_kg` (`striker_mass`, at fixed
striker radius), `wall_youngs_pa` (`wall_youngs`), `wall_poisson`, `bead_radius_m`
(`bead_radius`), `bead_density_kg_m3` (`bead_density`), `bead_youngs_pa` (`bead_youngs`),
`bead_poisson`, `sensor_beta`, `sensor_f0_hz` (`sensor_f0`), `precompression_n`
(`precompression`), `bead_yield_stress_pa` (`yield_stress`) and `yield_force_n`
(`yield_force`, the bead-bead contacts' yield force; all contacts' yield forces scale
together as the yield stress cubed), and `bead_masses_kg` (`bead_masses`, one per bead: N
values, at fixed radii). The bead parameters act on the beads, not on the striker; for a
chain of unequal beads they read bead 1's value and scale every bead's value in proportion
to it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from .caller import user_stacklevel
from .chain import ChainSetup
from .materials import sphere_volume_m3


class Parameter(NamedTuple):
    """A physical parameter of a `ChainSetup`.

    **Fields:** `name` (the registry key), `unit` (SI unit, "" if dimensionless),
    `meaning`, `get(setup) -> array` and `set(setup, value) -> setup` (pure, differentiable),
    `per_bead` (one value per bead), `public_name` (what a user writes and reads).
    """

    name: str
    unit: str
    meaning: str
    get: Callable
    set: Callable
    per_bead: bool = False
    public_name: str = ""


def _field(name: str) -> Callable:
    return lambda setup: getattr(setup, name)


def _setter(name: str):
    return lambda setup, value: eqx.tree_at(
        lambda s: getattr(s, name), setup, jnp.asarray(value, dtype=jnp.float64)
    )


def _bead_scalar_get(name: str):
    return lambda setup: getattr(setup, name)[0]


def _bead_scalar_set(name: str):
    def set_value(setup, value):
        old = getattr(setup, name)
        return eqx.tree_at(lambda s: getattr(s, name), setup, old * (value / old[0]))

    return set_value


def _set_bead_masses(setup, mass_kg):
    return eqx.tree_at(
        lambda s: s.bead_density_kg_m3, setup, mass_kg / sphere_volume_m3(setup.bead_radius_m)
    )


def _set_striker_mass(setup, mass_kg):
    return eqx.tree_at(
        lambda s: s.striker_density_kg_m3, setup, mass_kg / sphere_volume_m3(setup.striker_radius_m)
    )


def _set_yield_force(setup, force_n):
    current = setup.contact_yield_force_n()[1 if setup.n_beads > 1 else 0]
    stress = setup.bead_yield_stress_pa * (force_n / current) ** (1.0 / 3.0)
    return eqx.tree_at(lambda s: s.bead_yield_stress_pa, setup, stress)


def _scalar(name, field, unit, meaning) -> Parameter:
    return Parameter(name, unit, meaning, _field(field), _setter(field), public_name=field)


def _bead(name, field, unit, meaning) -> Parameter:
    return Parameter(name, unit, meaning, _bead_scalar_get(field), _bead_scalar_set(field), public_name=field)


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        _scalar("eta", "eta_s", "s", "viscoelastic time eta of F_v = eta kappa d(delta^3/2)/dt"),
        _scalar("mu", "mu", "", "track friction coefficient (force mu m g)"),
        _scalar("mu_star", "mu_star", "", "thwarted-rotation friction, kappa* = (1+mu*) kappa"),
        _scalar("striker_velocity", "striker_velocity_m_s", "m/s", "impact velocity"),
        Parameter(
            "striker_mass", "kg", "striker mass at fixed striker radius",
            lambda s: s.striker_mass_kg, _set_striker_mass, public_name="striker_mass_kg",
        ),
        _scalar("wall_youngs", "wall_youngs_pa", "Pa", "Young's modulus of the wall"),
        _scalar("wall_poisson", "wall_poisson", "", "Poisson ratio of the wall"),
        _bead("bead_radius", "bead_radius_m", "m", "bead radius (every bead; striker unchanged)"),
        _bead("bead_density", "bead_density_kg_m3", "kg/m^3", "bead density (every bead)"),
        _bead("bead_youngs", "bead_youngs_pa", "Pa", "bead Young's modulus (every bead)"),
        _bead("bead_poisson", "bead_poisson", "", "bead Poisson ratio (every bead)"),
        _scalar("sensor_beta", "sensor_beta", "", "embedded sensor mass ratio beta"),
        _scalar("sensor_f0", "sensor_f0_hz", "Hz", "embedded sensor resonance f0"),
        _scalar("precompression", "precompression_n", "N", "static preload (> 0)"),
        _scalar("yield_stress", "bead_yield_stress_pa", "Pa",
                "bead yield stress of the elastic-plastic contacts (plasticity=True)"),
        Parameter(
            "yield_force", "N", "yield force of the bead-bead contacts (plasticity=True; "
            "all contacts' yield forces scale together, F_Y ~ yield stress^3)",
            lambda s: s.contact_yield_force_n()[1 if s.n_beads > 1 else 0], _set_yield_force,
            public_name="yield_force_n",
        ),
        Parameter(
            "bead_masses", "kg", "mass of each bead at fixed radius (N parameters)",
            lambda s: s.bead_mass_kg, _set_bead_masses, per_bead=True, public_name="bead_masses_kg",
        ),
    )
}

# public name -> registry key
_KEY_OF_PUBLIC = {p.public_name: p.name for p in PARAMETERS.values()}


class ParameterNameWarning(FutureWarning):
    """A parameter written with its previous name (`eta` for `eta_s`): accepted for one
    release; the message says the name to write."""


def resolve_key(name: str, key_of_public: Mapping[str, str], public_of: Callable[[str], str | None],
                where: str | None, unknown: Callable[[], Exception]) -> str:
    """The key of the parameter a user named `name` in a registry of parameters (this one, or
    `fitting.parameters`' of fitted ones), written either way: `key_of_public` maps public names
    to keys, `public_of(key)` is a key's public name (None: no such key). A previous name warns
    once, one line (`ParameterNameWarning`), naming the name to write and, where given, `where`
    (the argument, option or file `name` was written in). A name of neither spelling raises
    `unknown()`. Code that holds a key indexes its registry instead: a key is a previous name
    too."""
    if name in key_of_public:
        return key_of_public[name]
    public = public_of(name)
    if public is None:
        raise unknown()
    if public != name:
        warnings.warn(f"{f'{where}: ' if where else ''}{name!r} is now called {public!r}; write {public} "
                      "(the old name is accepted until the next release).", ParameterNameWarning,
                      stacklevel=user_stacklevel())
    return name


def relabel(label: str, rename: Callable[[str], str]) -> str:
    """`label` with its parameter's name renamed, the instance kept:
    `striker_velocity[run1]` -> `rename("striker_velocity") + "[run1]"`, `bead_masses[3]` ->
    `rename("bead_masses") + "[3]"`."""
    name, bracket, instance = label.partition("[")
    return rename(name.strip()) + bracket + instance


def public_names(*, per_bead: bool = True) -> tuple[str, ...]:
    """The names a user writes, one per parameter, in registry order (without the per-bead
    ones when `per_bead` is False)."""
    return tuple(p.public_name for p in PARAMETERS.values() if per_bead or not p.per_bead)


def resolve_name(name: str, *, where: str | None = None) -> str:
    """The registry key of the parameter a user named `name`, written either way: its public
    name (`wall_youngs_pa`) or its previous, short one (`wall_youngs`), which warns once, one
    line (`ParameterNameWarning`), naming `where` (the argument, option or file it was written
    in: `params`, `--params`) where given. An unknown name raises a ValueError listing the
    public names."""
    return resolve_key(
        name, _KEY_OF_PUBLIC, lambda key: PARAMETERS[key].public_name if key in PARAMETERS else None, where,
        lambda: ValueError(f"unknown parameter {name!r}{f' in {where}' if where else ''}; valid parameters: "
                           f"{', '.join(public_names())}."))


def public_name(label: str) -> str:
    """What a user sees for a registry key or a per-bead label: `eta` -> `eta_s`,
    `bead_masses[3]` -> `bead_masses_kg[3]`; other names unchanged."""
    return relabel(label, lambda name: PARAMETERS[name].public_name if name in PARAMETERS else name)


def _held(name: str) -> Parameter:
    """The parameter of a name the code holds (a registry key or a public name), unresolved."""
    return PARAMETERS[_KEY_OF_PUBLIC.get(name, name)]


def key_values(setup: ChainSetup, keys: Sequence[str]) -> dict[str, jax.Array]:
    """The current values of the parameters `keys` (names the code holds: registry keys or
    public names, not resolved, so nothing warns) in `setup` (scalars, or (N,) for per-bead
    ones), SI, keyed as given."""
    return {key: jnp.asarray(_held(key).get(setup)) for key in keys}


def with_keys(setup: ChainSetup, values: Mapping[str, jax.Array]) -> ChainSetup:
    """`setup` with the parameters `values`' keys name (as in `key_values`) set to `values`
    (SI; pure and differentiable)."""
    for key, value in values.items():
        setup = _held(key).set(setup, value)
    return setup


def parameter_values(setup: ChainSetup, params: Sequence[str]) -> dict[str, jax.Array]:
    """The current values of `params` (either spelling, `resolve_name`: a previous name warns)
    in `setup` (scalars, or (N,) for per-bead ones), SI, keyed as given."""
    keys = [resolve_name(name, where="params") for name in params]
    values = key_values(setup, keys)
    return {name: values[key] for name, key in zip(params, keys)}


def with_parameters(setup: ChainSetup, values: Mapping[str, jax.Array]) -> ChainSetup:
    """`setup` with the named parameters (either spelling, `resolve_name`: a previous name
    warns) set to `values` (SI; pure and differentiable)."""
    return with_keys(setup, {resolve_name(name, where="values"): value for name, value in values.items()})
