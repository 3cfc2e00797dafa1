"""Rate-dependent contact forces: the dissipation laws, and how they join the elastic force.

A dissipation law is an `equinox.Module` whose fields are its coefficients; its `force` is
the term it adds to a contact's elastic force while the contact is closed, from the
overlap (m) and the overlap rate (m/s, positive while the beads approach). `total_force`
sums the terms of every law of a contact with its elastic force and clips the sum at zero:
beads without adhesion cannot pull on each other, so during fast unloading they separate
instead (LAMMPS's `limit_damping`).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import contact
from ..validation import check_positive_parameters


def _float64(value) -> jax.Array:
    """A law's coefficient as a float64 array (the field converter of every law here)."""
    return jnp.asarray(value, dtype=jnp.float64)


class AbstractDissipation(eqx.Module):
    """A rate-dependent normal force of a closed contact."""

    @abc.abstractmethod
    def force(self, overlap_m, overlap_rate_m_s, kappa_n_m1p5):
        """The law's force at `overlap_m` (m, > 0) and `overlap_rate_m_s` (m/s), N
        (compression positive; `total_force` masks it where the contact is open). A contact
        of zero Hertz stiffness `kappa_n_m1p5` (N/m^{3/2}) is no contact (a free end)."""

    @abc.abstractmethod
    def is_active(self):
        """Whether the law dissipates at all (its coefficient is not 0), bool array."""

    @property
    def native_name(self) -> str | None:
        """The native kernels' name of this law (`hertzchain.laws.registry`), or None where
        only the JAX kernels run it."""
        from .registry import native_name

        return native_name(self)

    def rate_slot_coefficient(self):
        """For a law of the native kernels' rate slot (its force a coefficient times the
        overlap rate, `chain_laws.h`'s `RateSlotCoefficient`; its native name a
        `native.RATE_LAW_DEFINES` key): the coefficient the kernels take. None: not such a law."""
        return None


class Viscoelastic(AbstractDissipation):
    """Kuwabara-Kono damping, the paper's: $F_v = \\eta\\kappa\\,\\partial_t(\\delta^{3/2})
    = \\tfrac32\\eta\\kappa\\,\\delta^{1/2}\\dot\\delta$. It vanishes with $\\delta^{1/2}$ at
    contact onset and separation, so the force is continuous there.

    **Arguments:**

    - `eta_s`: viscoelastic time $\\eta$, s (>= 0).
    """

    eta_s: jax.Array = eqx.field(converter=_float64, default=0.0)

    def force(self, overlap_m, overlap_rate_m_s, kappa_n_m1p5):
        _, root = contact._positive_part_and_root(overlap_m)
        return (1.5 * self.eta_s * kappa_n_m1p5 * root) * overlap_rate_m_s

    def is_active(self):
        return self.eta_s != 0.0


class Dashpot(AbstractDissipation):
    """A linear dashpot $\\gamma\\dot\\delta$ while in contact, the damping of much of the
    granular-crystal literature (Herbold & Nesterenko, PRE 75, 021304, 2007). It does not
    vanish at onset: the force jumps by $\\gamma\\dot\\delta$ there.

    **Arguments:**

    - `gamma_n_s_m`: $\\gamma$, N s/m (>= 0).
    """

    gamma_n_s_m: jax.Array = eqx.field(converter=_float64, default=0.0)

    def force(self, overlap_m, overlap_rate_m_s, kappa_n_m1p5):
        return jnp.where(kappa_n_m1p5 > 0.0, self.gamma_n_s_m, 0.0) * overlap_rate_m_s

    def is_active(self):
        return self.gamma_n_s_m != 0.0

    def rate_slot_coefficient(self):
        return self.gamma_n_s_m


def total_force(elastic_n, overlap_m, overlap_rate_m_s, kappa_n_m1p5, dissipation=()):
    """Total normal force of contacts, N: the elastic force `elastic_n` (N, from the contact
    law) plus every term of the laws in `dissipation` (a sequence of `AbstractDissipation`)
    while the contact is closed ($\\delta > 0$), clipped at zero; 0 when open. Without
    dissipation, the elastic force itself."""
    if not dissipation:
        return elastic_n
    terms = [law.force(overlap_m, overlap_rate_m_s, kappa_n_m1p5) for law in dissipation]
    rate_force = terms[0]
    for term in terms[1:]:
        rate_force = rate_force + term
    return jnp.where(overlap_m > 0.0, jnp.maximum(elastic_n + rate_force, 0.0), 0.0)


def is_damped(dissipation):
    """Whether any law of `dissipation` dissipates, bool array (False for none)."""
    active = jnp.asarray(False)
    for law in dissipation:
        active = active | law.is_active()
    return active


class VelocitySquared(AbstractDissipation):
    """Velocity-squared contact dissipation, $F_d = c\\,|\\dot\\delta|\\,\\dot\\delta$ while in
    contact: the loss Vergara (PRL 104, 118001, 2010) proposed for dry granular chains, a
    drag that grows with the square of the beads' relative speed (a dissipation that grows
    with amplitude, which a viscous law's does not). The sign follows $\\dot\\delta$, so it
    resists both approach and separation; the sum with the elastic force is clipped at 0
    (`total_force`), so beads never pull. Smooth ($C^1$) in $\\dot\\delta$, and of the
    dashpot's form $\\gamma\\dot\\delta$ with $\\gamma = c|\\dot\\delta|$. A weak one takes
    $\\Delta E = \\tfrac{10}{7}\\,c\\,v^2\\delta_m$ from a binary Hertz collision at relative speed
    v and largest overlap $\\delta_m$ ($c\\int|\\dot\\delta|^3dt$ along the elastic collision).

    **Arguments:**

    - `c_n_s2_m2`: c, N s^2/m^2 (>= 0).
    """

    c_n_s2_m2: jax.Array = eqx.field(converter=_float64, default=0.0)

    def __check_init__(self):
        check_positive_parameters("VelocitySquared", (("c_n_s2_m2", self.c_n_s2_m2, "N s^2/m^2"),), zero_ok=True)

    def force(self, overlap_m, overlap_rate_m_s, kappa_n_m1p5):
        return jnp.where(kappa_n_m1p5 > 0.0, self.c_n_s2_m2, 0.0) * jnp.abs(overlap_rate_m_s) * overlap_rate_m_s

    def is_active(self):
        return self.c_n_s2_m2 != 0.0

    def rate_slot_coefficient(self):
        return self.c_n_s2_m2


class HuntCrossley(AbstractDissipation):
    """Hunt-Crossley hysteretic damping on Hertz's law, $F_d = \\tfrac32\\alpha\\,\\kappa
    \\delta^{3/2}\\dot\\delta$ while in contact (Hunt & Crossley, J. Appl. Mech. 42, 440, 1975):
    a damping force proportional to the elastic force, so it vanishes with $\\delta^{3/2}$ at
    contact onset (no jump, unlike a dashpot's) and a preloaded contact's linear damping
    coefficient is $\\tfrac32\\alpha F_0$: it scales with the load the contact carries, where
    Kuwabara-Kono's $\\tfrac32\\eta\\kappa\\delta_0^{1/2}$ scales as $F_0^{1/3}$. A weak one
    takes $\\Delta E = \\tfrac{8}{15}\\cdot\\tfrac32\\alpha\\kappa\\,v\\,\\delta_m^{5/2} =
    \\alpha v\\cdot\\mu v^2$ from a binary Hertz collision at relative speed v (reduced mass
    $\\mu$, largest overlap $\\delta_m$): a restitution $e = \\sqrt{1 - 2\\alpha v} \\approx 1 -
    \\alpha v$, falling with the impact speed. The sum with the elastic force is clipped at 0
    (`total_force`), so beads never pull.

    **Arguments:**

    - `alpha_s_m`: $\\alpha$, s/m (>= 0).
    """

    alpha_s_m: jax.Array = eqx.field(converter=_float64, default=0.0)

    def __check_init__(self):
        check_positive_parameters("HuntCrossley", (("alpha_s_m", self.alpha_s_m, "s/m"),), zero_ok=True)

    def force(self, overlap_m, overlap_rate_m_s, kappa_n_m1p5):
        return (1.5 * self.alpha_s_m * contact.hertz_force(overlap_m, kappa_n_m1p5)) * overlap_rate_m_s

    def is_active(self):
        return self.alpha_s_m != 0.0
