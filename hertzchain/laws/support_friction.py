"""Friction at a bead's supports with micro-slip: an Iwan element acting on its displacement.

A bead resting on supports (rods, a V-groove) is held by friction at the points it touches
them. As the bead moves, the edges of those contacts slip first and the centres later
(Mindlin-Deresiewicz micro-slip): a force that is a stiff spring at the smallest motion,
grows less than linearly, and saturates at the Coulomb force once all slips. Iwan's model
(J. Appl. Mech. 33, 893, 1966) writes it as E Jenkins elements in parallel, each a spring
$K/E$ in series with a slider that slips when its spring's stretch exceeds $\\phi_j$. The
fraction of the elements that have slipped by a stretch $\\phi$ is $(\\phi/\\phi_{max})^p$:
$p = 1$ spreads the $\\phi_j$ uniformly over $(0, \\phi_{max}]$, and $p < 1$ puts more of them
at small stretches, as Segalman's power-law distribution of joint strengths does (J. Appl.
Mech. 72, 752, 2005: his $\\chi = p - 1$), so that a cycle dissipates as $A^{2+p}$ rather than
Mindlin's $A^3$ (measured joints dissipate with exponents between 2 and 3). The elements sit at the
distribution's midpoints, $\\phi_j = \\phi_{max}((j - \\tfrac12)/E)^{1/p}$.
Element j's slider position $s_j$ is its history: after a move to x, $s_j$ follows just
enough that $|x - s_j| \\le \\phi_j$. The force on the bead is

$F = -\\frac{K}{E}\\sum_j (x - s_j)$ (N, resisting the displacement from where it stuck).

For many elements: on first loading $F = -Kx\\,(1 - (x/\\phi_{max})^p/(1 + p))$ up to full slip at
$x = \\phi_{max}$, where it is the Coulomb force $F_s = K\\phi_{max}\\,p/(1 + p)$ ($K\\phi_{max}/2$
for the uniform spread). A cycle of amplitude A follows Masing's rule and dissipates
$W = \\sum_j 4\\frac{K}{E}\\phi_j(A - \\phi_j)_+$, which is
$4KpA^{2+p}/(\\phi_{max}^p(1 + p)(2 + p))$ below full slip ($\\tfrac23 KA^3/\\phi_{max}$, the $A^3$
law of micro-slip, for $p = 1$) and $4F_sA - 4Kp\\phi_{max}^2/(2 + p)$ above it, Coulomb's
$4F_sA$ for $A \\gg \\phi_{max}$. Under a small harmonic motion the dissipation per cycle over
$\\pi A^2$ times the loss of in-phase stiffness is $4p/(\\pi(2 + p))$: a small p softens the
supports more for the energy it takes.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ..validation import check_positive_parameters


class IwanSupport(eqx.Module):
    """Micro-slip friction at the supports of every bead (see the module docstring).

    **Arguments:**

    - `stiffness_n_m`: K, the stiffness of the supports before anything slips, N/m (> 0).
    - `slip_displacement_m`: $\\phi_{max}$, the displacement at which all of the contact
      slips, m (> 0); the Coulomb force is $K\\phi_{max}/2$.
    - `elements`: E, the number of Jenkins elements (static, default 16).
    - `slip_power`: p, the power of the elements' spread: the fraction slipped by a stretch
      $\\phi$ is $(\\phi/\\phi_{max})^p$ (1, the default: uniform; Segalman's $\\chi + 1$), > 0.

    K, $\\phi_{max}$ and p are one value for every bead or, in a `DrivenChain`, (n,) one per bead.
    """

    stiffness_n_m: jax.Array
    slip_displacement_m: jax.Array
    elements: int = eqx.field(static=True)
    slip_power: jax.Array

    def __init__(self, stiffness_n_m, slip_displacement_m, elements: int = 16, slip_power=1.0):
        self.stiffness_n_m = jnp.asarray(stiffness_n_m, dtype=jnp.float64)
        self.slip_displacement_m = jnp.asarray(slip_displacement_m, dtype=jnp.float64)
        if int(elements) != elements or elements < 1:
            raise ValueError(f"IwanSupport: elements must be a whole number >= 1, got {elements}.")
        self.elements = int(elements)
        self.slip_power = jnp.asarray(slip_power, dtype=jnp.float64)

    def __check_init__(self):
        check_positive_parameters("IwanSupport", (("stiffness_n_m", self.stiffness_n_m, "N/m"),
                                             ("slip_displacement_m", self.slip_displacement_m, "m"),
                                             ("slip_power", self.slip_power, "1")))

    @property
    def coulomb_force_n(self) -> jax.Array:
        """The force of full slip, $F_s = K\\phi_{max}\\,p/(1 + p)$ for many elements, N: the
        sum of the elements' $K\\phi_j/E$."""
        return (self.stiffness_n_m / self.elements) * jnp.sum(self._slip_at(self.slip_displacement_m), axis=0)

    def _slip_at(self, displacement_m):
        """$\\phi_j$ (E, ...) broadcasting with the displacements (and with p and $\\phi_{max}$), m."""
        fraction = (jnp.arange(self.elements) + 0.5) / self.elements
        fraction = fraction.reshape((self.elements,) + (1,) * max(jnp.ndim(displacement_m), jnp.ndim(self.slip_power)))
        return fraction ** (1.0 / self.slip_power) * self.slip_displacement_m

    def initial_state(self, displacement_m):
        """Every slider where the bead is at rest: (E, ...) slider positions, m."""
        return jnp.broadcast_to(displacement_m, (self.elements,) + jnp.shape(displacement_m)) + 0.0

    def update_state(self, slider_m, displacement_m):
        """The sliders after a move to `displacement_m`: each follows just enough that its
        spring's stretch stays within $\\pm\\phi_j$, m. A slider that sticks keeps its
        position exactly (the stretch beyond $\\phi_j$ it moves by is an exact 0), and so does
        its derivative: a period map's row of a slider stuck throughout is exactly a unit row."""
        limit = self._slip_at(displacement_m)
        stretch = displacement_m - slider_m
        return slider_m + (stretch - jnp.clip(stretch, -limit, limit))

    def force(self, displacement_m, slider_m):
        """The supports' force on the bead, N (negative for a bead displaced to +x)."""
        return -(self.stiffness_n_m / self.elements) * jnp.sum(displacement_m - slider_m, axis=0)

    def energy(self, displacement_m, slider_m):
        """Energy stored in the elements' springs, J."""
        return 0.5 * (self.stiffness_n_m / self.elements) * jnp.sum((displacement_m - slider_m) ** 2, axis=0)
