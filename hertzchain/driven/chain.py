"""A precompressed chain of beads between a driven face and a fixed wall.

    driver (prescribed displacement u(t)) | bead 1 | bead 2 | ... | bead n | wall (fixed)
                                      contact 0  contact 1   ...  contact n-1  contact n

Contact 0 joins the driver face to bead 1, contact K joins bead K to bead K + 1, contact n
joins bead n to the wall; each has its own Hertz stiffness $\\kappa_k$ (N/m^{3/2}). A static
force $F_0$ (N) presses the whole stack together: without gravity every contact carries
$F_0$ at rest, with overlap $\\delta_k^0 = (F_0/\\kappa_k)^{2/3}$. Displacements $x_i$ are
measured from that equilibrium (positive towards the wall), so the overlaps are

$\\delta_0 = \\delta_0^0 + u - x_1$, $\\delta_k = \\delta_k^0 + x_k - x_{k+1}$,
$\\delta_n = \\delta_n^0 + x_n$,

and bead $i$ obeys $m_i\\ddot x_i = F_{i-1} - F_i - m_i\\gamma_i\\dot x_i$, with the contact
forces of `hertzchain.laws.Hertz` plus `hertzchain.laws.Viscoelastic` (Kuwabara-Kono damping
of coefficient `eta_s`), clipped at zero (the beads can separate), and a viscous drag
$-m\\gamma v$ on each bead (the driver and the wall are the frame at rest).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import contact, laws
from ..precision import require_float64


class DrivenChain(eqx.Module):
    """The physical constants of a driven, precompressed chain of n beads (all traceable).

    **Fields:**

    - `bead_mass_kg`: (n,) bead masses, kg.
    - `contact_kappa_n_m1p5`: (n + 1,) Hertz stiffness of each contact, N/m^{3/2}:
      contact 0 = driver face-bead 1, contact K = bead K-bead K+1, contact n = bead n-wall.
    - `precompression_n`: () static force $F_0$ every contact carries at rest, N (> 0).
    - `damping_rate_per_s`: (n,) viscous damping rate $\\gamma$ of each bead, 1/s (force
      $-m\\gamma v$; a lone bead's damping ratio is $\\gamma / (2\\omega_0)$).
    - `eta_s`: () Kuwabara-Kono damping time of every contact, s (default 0; None inside
      compiled runs where it is 0, see `for_kernel`).

    Build one from material constants with `DrivenChain.from_materials`, or directly from
    arrays; `eqx.tree_at` replaces a field (e.g. for a fit). Every field is a float64
    array leaf, so `jax.jacfwd` and `jax.vmap` go through it.
    """

    bead_mass_kg: jax.Array
    contact_kappa_n_m1p5: jax.Array
    precompression_n: jax.Array
    damping_rate_per_s: jax.Array
    eta_s: jax.Array | None

    def __init__(self, bead_mass_kg, contact_kappa_n_m1p5, precompression_n, damping_rate_per_s, eta_s=0.0):
        require_float64("DrivenChain")
        self.bead_mass_kg = jnp.atleast_1d(jnp.asarray(bead_mass_kg, dtype=jnp.float64))
        n = self.bead_mass_kg.shape[0]
        self.contact_kappa_n_m1p5 = jnp.asarray(contact_kappa_n_m1p5, dtype=jnp.float64)
        self.precompression_n = jnp.asarray(precompression_n, dtype=jnp.float64)
        self.damping_rate_per_s = jnp.broadcast_to(jnp.asarray(damping_rate_per_s, dtype=jnp.float64), (n,))
        self.eta_s = jnp.asarray(eta_s, dtype=jnp.float64)
        if self.bead_mass_kg.ndim != 1 or n < 1:
            raise ValueError(f"bead_mass_kg: expected an (n,) array of bead masses in kg, got shape "
                             f"{self.bead_mass_kg.shape}.")
        if self.contact_kappa_n_m1p5.shape != (n + 1,):
            raise ValueError(
                f"contact_kappa_n_m1p5: expected {n + 1} stiffnesses (driver, {n - 1} between beads, "
                f"wall) for {n} beads, got shape {self.contact_kappa_n_m1p5.shape}."
            )
        if self.precompression_n.ndim != 0:
            raise ValueError(f"precompression_n: expected one static force in N, got shape "
                             f"{self.precompression_n.shape}.")
        if self.eta_s.ndim != 0:
            raise ValueError(f"eta_s: expected one damping time in s, got shape {self.eta_s.shape}.")
        _check_concrete_positive("bead_mass_kg", self.bead_mass_kg, "kg")
        _check_concrete_positive("contact_kappa_n_m1p5", self.contact_kappa_n_m1p5, "N/m^1.5")
        _check_concrete_positive("precompression_n", self.precompression_n, "N")
        _check_concrete_nonnegative("damping_rate_per_s", self.damping_rate_per_s, "1/s")
        _check_concrete_nonnegative("eta_s", self.eta_s, "s")

    @property
    def n_beads(self) -> int:
        """Number of beads n."""
        return self.bead_mass_kg.shape[0]

    @classmethod
    def from_materials(
        cls,
        *,
        n_beads: int,
        bead_radius_m: float,
        bead_youngs_pa: float,
        bead_poisson: float,
        driver_youngs_pa: float,
        driver_poisson: float,
        wall_youngs_pa: float,
        wall_poisson: float,
        precompression_n: float,
        damping_rate_per_s: float = 0.0,
        bead_mass_kg: float | None = None,
        bead_density_kg_m3: float | None = None,
        eta_s: float = 0.0,
    ) -> DrivenChain:
        """n identical spheres of radius `bead_radius_m` between a flat driver face and a flat
        wall: Hertz sphere-flat stiffness (`contact.kappa_sphere_flat`) at the driver and the
        wall, sphere-sphere (`contact.kappa_sphere_sphere`) between beads. Give the bead mass
        either directly (`bead_mass_kg`) or through `bead_density_kg_m3` (a full sphere).
        Moduli in Pa (`inf` for a rigid face), Poisson ratios dimensionless, force in N,
        damping rate in 1/s (the same for every bead), `eta_s` in s."""
        if (bead_mass_kg is None) == (bead_density_kg_m3 is None):
            raise ValueError("from_materials: give exactly one of bead_mass_kg (kg) or bead_density_kg_m3 (kg/m^3).")
        if int(n_beads) != n_beads or n_beads < 1:
            raise ValueError(f"n_beads: expected a positive whole number of beads, got {n_beads}.")
        radius = jnp.asarray(bead_radius_m, dtype=jnp.float64)
        if bead_mass_kg is None:
            bead_mass_kg = 4.0 / 3.0 * np.pi * radius**3 * bead_density_kg_m3
        driver = contact.kappa_sphere_flat(radius, bead_youngs_pa, bead_poisson, driver_youngs_pa, driver_poisson)
        wall = contact.kappa_sphere_flat(radius, bead_youngs_pa, bead_poisson, wall_youngs_pa, wall_poisson)
        between = contact.kappa_sphere_sphere(radius, bead_youngs_pa, bead_poisson, radius, bead_youngs_pa,
                                              bead_poisson)
        n = int(n_beads)
        kappa = jnp.concatenate([jnp.atleast_1d(driver), jnp.full((n - 1,), between), jnp.atleast_1d(wall)])
        return cls(
            bead_mass_kg=jnp.full((n,), bead_mass_kg, dtype=jnp.float64),
            contact_kappa_n_m1p5=kappa,
            precompression_n=precompression_n,
            damping_rate_per_s=jnp.full((n,), damping_rate_per_s, dtype=jnp.float64),
            eta_s=eta_s,
        )

    def for_kernel(self) -> DrivenChain:
        """This chain as the compiled runs take it: `eta_s` replaced by None where it is a
        concrete 0, so that the kernel leaves the Kuwabara-Kono term out (the same numbers,
        about 1.5× faster). A traced `eta_s` (e.g. one being fitted) stays."""
        if self.eta_s is None or isinstance(self.eta_s, jax.core.Tracer) or np.any(np.asarray(self.eta_s) != 0.0):
            return self
        return eqx.tree_at(lambda c: c.eta_s, self, None)

    def static_overlap_m(self) -> jax.Array:
        """(n + 1,) overlap of every contact at rest, $(F_0/\\kappa_k)^{2/3}$, m."""
        return laws.Hertz().overlap_at_force(self.precompression_n, laws.ContactConstants(self.contact_kappa_n_m1p5))

    def contact_stiffness_n_m(self) -> jax.Array:
        """(n + 1,) linear stiffness of every contact about the static state, the Hertz
        law's tangent stiffness $dF/d\\delta = \\tfrac32\\kappa^{2/3}F_0^{1/3}$, N/m."""
        constants = laws.ContactConstants(self.contact_kappa_n_m1p5)
        return laws.Hertz().stiffness_at_force(self.precompression_n, constants)

    def highest_frequency_bound_hz(self) -> jax.Array:
        """An upper bound on the chain's highest linear mode frequency about the static state,
        Hz (Gershgorin's bound on $M^{-1}K$: $\\omega^2 \\le \\max_i 2(k_{i-1} + k_i)/m_i$)."""
        k = self.contact_stiffness_n_m()
        # operators and methods only: the same code on NumPy leaves (checks of concrete inputs)
        return (2.0 * (k[:-1] + k[1:]) / self.bead_mass_kg).max() ** 0.5 / (2.0 * np.pi)


def _is_concrete(value) -> bool:
    return not isinstance(value, jax.core.Tracer)


def _check_concrete_positive(name: str, value, unit: str) -> None:
    if _is_concrete(value) and not (np.all(np.asarray(value) > 0.0) and np.all(np.isfinite(np.asarray(value)))):
        raise ValueError(f"{name}: every value must be finite and > 0 ({unit}), got {np.asarray(value)}.")


def _check_concrete_nonnegative(name: str, value, unit: str) -> None:
    if _is_concrete(value) and not (np.all(np.asarray(value) >= 0.0) and np.all(np.isfinite(np.asarray(value)))):
        raise ValueError(f"{name}: every value must be finite and >= 0 ({unit}), got {np.asarray(value)}.")
