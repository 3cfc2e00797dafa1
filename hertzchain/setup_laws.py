"""A `ChainSetup`'s laws read back under the attribute names of its former keywords.

Functions of a setup, which `ChainSetup` exposes as read-only properties of the same names
(`setup.eta_s`, `setup.power_law`, ...): the coefficients of its dissipation and contact
laws, sweepable and fittable through them (`eqx.tree_at(lambda s: s.eta_s, ...)` changes
the law's coefficient) and written to result files, and the kind of its contact law.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from . import laws

if TYPE_CHECKING:
    from .chain import ChainSetup

# The law coefficients a setup exposes as attributes (`ChainSetup.eta_s`, ...): sweepable,
# fittable and written to result files as before.
LAW_ATTRIBUTES = ("eta_s", "dashpot_n_s_m", "contact_exponent", "exponent_reference_overlap_m")


def law_attributes(setup: ChainSetup) -> tuple[str, ...]:
    """The names of `LAW_ATTRIBUTES` that are coefficients of this setup's laws (so
    `eqx.tree_at(lambda s: s.eta_s, ...)` changes them): `eta_s` and `dashpot_n_s_m`,
    and with `laws.PowerLaw` its exponent and reference overlap."""
    return LAW_ATTRIBUTES if power_law(setup) else LAW_ATTRIBUTES[:2]


def eta_s(setup: ChainSetup) -> jax.Array:
    """Viscoelastic time of the setup's `laws.Viscoelastic`, s."""
    return setup.dissipation[0].eta_s


def dashpot_n_s_m(setup: ChainSetup) -> jax.Array:
    """Coefficient of the setup's `laws.Dashpot`, N s/m."""
    return setup.dissipation[1].gamma_n_s_m


def plasticity(setup: ChainSetup) -> bool:
    """Whether the contact law is elastic-plastic (reads the largest overlap so far)."""
    return setup.contact_law.has_history


def plastic_law(setup: ChainSetup) -> str:
    """The elastic-plastic law's name ("thornton" or "jackson_green"; "thornton" for
    elastic contacts, the former default)."""
    return setup.contact_law.native_name if setup.contact_law.has_history else "thornton"


def power_law(setup: ChainSetup) -> bool:
    """Whether the contacts follow `laws.PowerLaw`."""
    return isinstance(setup.contact_law, laws.PowerLaw)


def contact_exponent(setup: ChainSetup) -> jax.Array:
    """Exponent of the contact law (1.5 unless `laws.PowerLaw`)."""
    return setup.contact_law.exponent if power_law(setup) else jnp.asarray(1.5)


def exponent_reference_overlap_m(setup: ChainSetup) -> jax.Array:
    """Reference overlap of `laws.PowerLaw`, m (its default 10 um for other laws)."""
    return setup.contact_law.reference_overlap_m if power_law(setup) else jnp.asarray(1e-5)
