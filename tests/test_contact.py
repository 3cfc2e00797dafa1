import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain as hc
from hertzchain import contact
from hertzchain.materials import BEAD_STEEL


def test_kappa_of_paper_beads_is_12_N_per_um_1p5():
    kappa = contact.kappa_sphere_sphere(0.013, 203e9, 0.3, 0.013, 203e9, 0.3)
    assert float(kappa) * 1e-9 == pytest.approx(12.0, rel=5e-3)
    assert float(kappa) * 1e-9 == pytest.approx(11.9900, abs=1e-3)


def test_wall_kappa_steel_and_rigid_relative_to_bead_bead():
    bead = contact.kappa_sphere_sphere(0.013, 203e9, 0.3, 0.013, 203e9, 0.3)
    steel = contact.kappa_sphere_flat(0.013, 203e9, 0.3, 203e9, 0.3)
    rigid = contact.kappa_sphere_flat(0.013, 203e9, 0.3, jnp.inf, 0.3)
    assert float(steel / bead) == pytest.approx(np.sqrt(2), rel=1e-12)
    assert float(rigid / bead) == pytest.approx(2 * np.sqrt(2), rel=1e-12)


def test_yield_force_and_overlap_from_sigma_y_match_paper():
    theta = BEAD_STEEL.theta_per_pa
    force = float(contact.yield_force(2e9, 0.013, theta, 0.013, theta))
    kappa = contact.kappa_sphere_sphere(0.013, 203e9, 0.3, 0.013, 203e9, 0.3)
    overlap = float(contact.overlap_at_force(force, kappa))
    assert force == pytest.approx(470.0, rel=0.02)  # paper: "roughly 470 N"
    assert overlap * 1e6 == pytest.approx(11.0, rel=0.07)  # paper: "about 11 um"
    # The paper's own closed form for identical beads, A = pi (theta R F)^(2/3).
    assert force == pytest.approx((np.pi * 2e9) ** 3 * (theta * 0.013) ** 2, rel=1e-12)


def test_hertz_gradients_are_finite_and_zero_at_contact_onset():
    for fn in (
        lambda d: contact.hertz_force(d, 1.2e10),
        lambda d: contact.hertz_potential(d, 1.2e10),
        lambda d: contact.contact_force(d, 0.1, 1.2e10, 2e-6)[1],
    ):
        for point in (0.0, -1e-9):
            g = jax.grad(fn)(jnp.asarray(point))
            assert np.isfinite(float(g)) and float(g) == 0.0
    # and the viscous term's derivative with respect to the rate at onset
    g = jax.grad(lambda r: contact.contact_force(0.0, r, 1.2e10, 2e-6)[1])(jnp.asarray(0.3))
    assert float(g) == 0.0
    # in contact, the written-out derivatives are the calculus ones: dF/d(delta) =
    # 3/2 kappa sqrt(delta), d2F/d(delta)2 = 3/4 kappa / sqrt(delta), dV/d(delta) = F
    for delta in (1e-9, 3.7e-6):
        d = jnp.asarray(delta)
        assert float(jax.grad(lambda x: contact.hertz_force(x, 1.2e10))(d)) == pytest.approx(
            1.5 * 1.2e10 * math.sqrt(delta), rel=1e-14)
        assert float(jax.grad(jax.grad(lambda x: contact.hertz_force(x, 1.2e10)))(d)) == pytest.approx(
            0.75 * 1.2e10 / math.sqrt(delta), rel=1e-14)
        assert float(jax.jacfwd(lambda x: contact.hertz_potential(x, 1.2e10))(d)) == pytest.approx(
            float(contact.hertz_force(d, 1.2e10)), rel=1e-14)


def test_binary_collision_time_matches_simulated_two_body_collision():
    # striker on a single free bead: contact 0 lasts one Hertz collision time
    setup = hc.ChainSetup(1, end="free", striker_velocity_m_s=0.2)
    run = hc.simulate(setup, t_end_s=150e-6, sample_interval_s=0.05e-6, contacts=(0,))
    force = np.asarray(run.forces_n["contact_0"])
    duration = np.sum(force > 0) * 0.05e-6
    mass = float(setup.bead_mass_kg[0])
    expected = float(contact.collision_time(mass / 2, setup.contact_kappa()[0], 0.2))
    assert duration == pytest.approx(expected, abs=0.1e-6)


def test_contact_laws_are_elementwise_in_any_layout():
    """The laws that both solvers call give the same numbers on (contacts,) and on
    (contacts, chains) arrays, and the viscous force is clipped at zero on fast unloading."""
    rng = np.random.default_rng(0)
    overlap = rng.normal(scale=2e-6, size=(7, 5))
    rate = rng.normal(scale=0.5, size=(7, 5))
    kappa = 1.2e10 * (1.0 + rng.random((7, 1)))
    spring = 3e8 * np.ones((7, 1))
    laws = (
        lambda o, r, k: contact.hertz_force(o, k),
        lambda o, r, k: contact.hertz_potential(o, k),
        lambda o, r, k: contact.contact_force(o, r, k, 2e-6)[1],
        lambda o, r, k: contact.spring_force(o, spring[: o.shape[0]]),
        lambda o, r, k: contact.spring_potential(o, spring[: o.shape[0]]),
    )
    for law in laws:
        whole = np.asarray(law(overlap, rate, kappa))
        for j in range(5):
            np.testing.assert_array_equal(whole[:, j : j + 1], law(overlap[:, j : j + 1], rate[:, j : j + 1], kappa))
    total = np.asarray(contact.contact_force(overlap, rate, kappa, 2e-6)[1])
    assert np.all(total >= 0.0) and np.any((overlap > 0) & (total == 0.0))  # clipped while in contact
    np.testing.assert_allclose(contact.hertz_force(overlap, kappa), kappa * np.maximum(overlap, 0) ** 1.5, rtol=1e-15)


def test_forward_mode_derivatives_finite_at_contact_onset():
    """Tangents (jax.jvp, what jacfwd pushes through the solvers) of every law are finite
    at and just outside contact, and zero there."""
    laws = (
        lambda d, r: contact.hertz_force(d, 1.2e10),
        lambda d, r: contact.hertz_potential(d, 1.2e10),
        lambda d, r: contact.contact_force(d, r, 1.2e10, 2e-6)[1],
    )
    for law in laws:
        for point in (0.0, -1e-9):
            _, tangent = jax.jvp(law, (jnp.asarray(point), jnp.asarray(0.3)), (jnp.asarray(1.0), jnp.asarray(1.0)))
            assert np.isfinite(float(tangent)) and float(tangent) == 0.0
    _, tangent = jax.jvp(lambda d: contact.hertz_force(d, 1.2e10), (jnp.asarray(1e-6),), (jnp.asarray(1.0),))
    assert float(tangent) == pytest.approx(1.5 * 1.2e10 * 1e-3, rel=1e-12)  # dF/dd = 3/2 kappa sqrt(d)
