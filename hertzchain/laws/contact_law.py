"""The abstract contact law: the rate-independent normal force of one contact.

A contact law is an `equinox.Module` whose fields are its own parameters (a power law's
exponent); the constants that the chain's geometry and materials give every contact
(Hertz stiffness, yield force, reduced radius, Poisson ratio, yield stress) come in as a
`ContactConstants`, arrays that broadcast with the overlaps. Laws with a history
(elastic-plastic contacts) read the largest overlap reached so far, their state; the others
ignore it. Every method is elementwise, written in `jax.numpy` and differentiable.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp


class ContactConstants(eqx.Module):
    """What the chain gives each contact, arrays that broadcast with the overlaps.

    **Fields:**

    - `kappa_n_m1p5`: Hertz stiffness $\\kappa$, N/m^{3/2} (0: no contact, a free end).
    - `yield_force_n`: the contact's yield force, N (the paper's mean-pressure estimate,
      `contact.yield_force`, where a chain builds it for a law to read; inf: never yields,
      e.g. a sensor spring); None where no law reads it.
    - `reduced_radius_m`: reduced radius $R^*$, m (the bead's for a flat); None likewise.
    - `poisson`: Poisson ratio of the yielding body; None likewise.
    - `yield_stress_pa`: the beads' yield stress, Pa; None likewise.
    """

    kappa_n_m1p5: jax.Array
    yield_force_n: jax.Array | None = None
    reduced_radius_m: jax.Array | None = None
    poisson: jax.Array | None = None
    yield_stress_pa: jax.Array | None = None


class AbstractContactLaw(eqx.Module):
    """A contact's elastic (rate-independent) force as a function of its overlap.

    Subclasses implement `parts` and `overlap_at_force`; a law whose force depends on the
    largest overlap so far sets `has_history = True`. Everything else (force, energy,
    tangent stiffness, the history update) follows from those.
    """

    has_history = False

    @abc.abstractmethod
    def parts(self, overlap_m, max_overlap_m, constants: ContactConstants):
        """(force N, stored elastic energy J, energy dissipated by the law so far J) at
        `overlap_m` (m), with `max_overlap_m` (m, >= `overlap_m`) the largest overlap so
        far (read by laws with a history only)."""

    @abc.abstractmethod
    def overlap_at_force(self, force_n, constants: ContactConstants):
        """Overlap at which a contact loaded for the first time carries `force_n`, m (0 at
        zero force, with finite derivatives)."""

    def force(self, overlap_m, max_overlap_m, constants: ContactConstants):
        """Elastic force, N (compression positive, 0 when apart)."""
        return self.parts(overlap_m, max_overlap_m, constants)[0]

    def energy(self, overlap_m, max_overlap_m, constants: ContactConstants):
        """Elastic energy stored in the contact, J."""
        return self.parts(overlap_m, max_overlap_m, constants)[1]

    def initial_state(self, overlap_m):
        """The history before any motion: the largest overlap so far is the current one, m."""
        return overlap_m

    def update_state(self, max_overlap_m, overlap_m):
        """The history after a move to `overlap_m`: the largest overlap so far, m."""
        return jnp.maximum(max_overlap_m, overlap_m)

    def tangent_stiffness(self, overlap_m, max_overlap_m, constants: ContactConstants):
        """$\\partial F/\\partial\\delta$ at fixed history, N/m: the stiffness that small
        oscillations about `overlap_m` see."""
        return jax.jvp(lambda d: self.force(d, max_overlap_m, constants), (overlap_m,),
                       (jnp.ones_like(overlap_m),))[1]

    def stiffness_at_force(self, force_n, constants: ContactConstants):
        """Tangent stiffness of a contact statically loaded to `force_n` for the first time, N/m."""
        overlap = self.overlap_at_force(force_n, constants)
        return self.tangent_stiffness(overlap, overlap, constants)

    def yield_force_n(self, constants: ContactConstants):
        """Force at which the contact leaves its elastic branch, N: for laws without one,
        the paper's mean-pressure estimate (`constants.yield_force_n`), which the yield
        check compares the forces with."""
        return constants.yield_force_n


    def native_rows(self, constants: ContactConstants) -> tuple:
        """Its parameters as the native kernels read them: the rows of their law array in
        order (`chain_kernel.cc`'s `LawRows`), each a value per contact or one for all
        (`native.run_full` lays them out). Hertz's law has none."""
        return ()
    @property
    def native_name(self) -> str | None:
        """The native kernels' name of this law (`batched.KernelFlags.law`), or None where
        only the JAX kernels run it (`hertzchain.laws.registry`)."""
        from .registry import native_name

        return native_name(self)
