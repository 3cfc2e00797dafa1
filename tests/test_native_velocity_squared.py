"""Velocity-squared contact dissipation (`laws.VelocitySquared`) in the native kernels' rate
slot: its forces, books and forward-mode derivatives against the JAX kernel and the general
solver, and the chains the slot cannot carry left to the JAX kernel."""

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    NEEDS_A_COMPILER,
    assert_forces_equal_the_jax_kernels,
    assert_jacfwd_equals_the_jax_kernels,
    ten_bead_batch,
)

import hertzchain as hc
from hertzchain import laws, native
from hertzchain.batched import kernel_flags, record_batched, solve_batched
from hertzchain.integrate import Recording, solve_stacked

pytestmark = NEEDS_A_COMPILER

# c = 3000 N s^2/m^2 at the 0.3-1 m/s impacts of `ten_bead_batch`: c v^2 is 270-3000 N against
# contact forces of ~1e3 N, a loss of the order the driven candidates use
C = 3000.0


def _chain(c=C, **kwargs):
    return ten_bead_batch(dissipation=(laws.VelocitySquared(c),), **kwargs)


def _native_target(setup, grid, flags) -> str:
    text = jax.jit(lambda s: record_batched(s, grid, Recording((2, 6)), flags).forces_n["wall"]).lower(setup).as_text()
    return re.findall(r"custom_call @(hertzchain_chain_full_forward\w*)", text)


@pytest.mark.parametrize("extra", [{}, {"mu": 0.19, "eta_s": 1e-6}, {"precompression_n": 2.0, "end": "free"}])
def test_forces_and_books_equal_the_jax_kernel_and_the_general_solver(extra):
    """The velocity-squared library runs the chain (its target, the rate slot on), and its
    forces and books equal the JAX kernel's to round-off; the general solver (`solve_stacked`,
    the reference `solve` step on the setup's laws) agrees within its own tolerance; the loss
    is real: the chains dissipate."""
    setup, grid = _chain(**extra)
    flags = kernel_flags(setup)
    assert flags.rate_law == "velocity_squared" and flags.viscous
    assert native.kernel_for(flags, None) == native.FusedKernel("full", "host")
    assert _native_target(setup, grid, flags._replace(ledger=False)) == [native.HOST_LIBRARIES["velocity_squared"].target("full")]
    ours, reference = assert_forces_equal_the_jax_kernels(setup, grid, books=True)
    assert ours.kernel == "native full (host)" and reference.kernel == "jax"
    energy = np.asarray(reference.initial_energy_j)
    for name in ("kinetic_j", "potential_j", "dissipated_j", "energy_error_j"):
        np.testing.assert_allclose(getattr(ours, name), getattr(reference, name), rtol=0, atol=1e-12 * energy.max())
    assert np.all(np.asarray(ours.dissipated_j) > 1e-3 * energy)
    general = solve_stacked(setup, grid, Recording((2, 6)))
    for name in ours.channel_names:
        scale = float(np.max(np.abs(general.forces_n[name])))
        np.testing.assert_allclose(ours.forces_n[name], general.forces_n[name], rtol=0, atol=1e-9 * scale)


def test_derivatives_in_the_coefficient_equal_jacfwd_through_the_jax_kernel():
    """`jax.jacfwd` in (c, eta, mu, striker speed) through the native kernel (the coefficient
    seeded in the rate slot, `chain_laws.h` on dual numbers) equals it through the JAX kernel
    to 1e-10 of each column's largest value."""
    base, grid = _chain(speeds=(0.3, 1.0))
    grid = hc.choose_time_grid(base, t_end_s=0.4e-3, sample_interval_s=2e-6)
    flags = kernel_flags(base, switched_on=("viscous", "friction"))._replace(ledger=False)
    assert flags.rate_law == "velocity_squared"
    ones = jnp.ones(base.eta_s.shape)

    def forces(q, kernel):
        setup = eqx.tree_at(lambda s: (s.dissipation[2].c_n_s2_m2, s.eta_s, s.mu, s.striker_velocity_m_s), base,
                            (q[0] * ones, q[1] * ones, q[2] * ones, q[3] * base.striker_velocity_m_s))
        out = record_batched(setup, grid, Recording((2, 6)), flags, kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([C, 1e-6, 0.19, 1.0])
    assert_jacfwd_equals_the_jax_kernels(forces, q)
    values = np.asarray(forces(q, "jax"))
    np.testing.assert_allclose(np.asarray(forces(q, "auto")), values, rtol=0, atol=2e-12 * np.max(np.abs(values)))


@pytest.mark.parametrize("extra, why", [
    ({"dashpot_n_s_m": 5.0}, "a dashpot holds the rate slot"),
    ({"contact_law": laws.PowerLaw(1.6, 1e-5)}, "its library has Hertz contacts only"),
])
def test_chains_the_rate_slot_cannot_carry_run_on_the_jax_kernel(extra, why):
    """A chain with a dashpot and velocity-squared dissipation, or velocity-squared
    dissipation on another contact law, is not given to a native kernel that would drop a
    law: the JAX kernel runs it, says so, and agrees with the general solver."""
    setup, grid = _chain(**extra)
    flags = kernel_flags(setup)
    assert (flags.rate_law == "velocity_squared") == ("dashpot_n_s_m" not in extra), why
    out = solve_batched(setup, grid, Recording((2,)), books=False)
    assert out.kernel == "jax", why
    reference = solve_stacked(setup, grid, Recording((2,)))
    for name in out.channel_names:
        scale = float(np.max(np.abs(reference.forces_n[name])))
        assert scale > 1.0
        np.testing.assert_allclose(out.forces_n[name], reference.forces_n[name], rtol=0, atol=1e-9 * scale)


def test_the_rate_slot_takes_one_law_by_its_name():
    """`native.run_full`'s rate slot holds one law, named: an unknown name is refused naming
    the known ones, and velocity-squared dissipation on another contact law naming the fix."""
    p = {name: jnp.zeros((2, 1)) for name in ("inv_mass", "kappa", "overlap0", "spring", "external")}
    p.update(eta=jnp.zeros(1), friction=jnp.zeros(1), dashpot=jnp.ones(1), dissipation=(laws.VelocitySquared(1.0),))
    x = jnp.zeros((2, 1))
    common = dict(dt_s=1e-7, steps_per_sample=1, n_samples=1, channels=(0,), viscous=True, friction=False,
                  preload=False, springs=False)
    with pytest.raises(ValueError, match=r"rate_law must be None or one of \('dashpot', 'velocity_squared'\)"):
        native.run_full(p, x, x, x, rate_law="dashpot_and_velocity_squared", **common)
    with pytest.raises(ValueError, match="rate_law='velocity_squared' needs law='hertz'"):
        native.run_full(p, x, x, x, rate_law="velocity_squared", law="thornton", **common)
