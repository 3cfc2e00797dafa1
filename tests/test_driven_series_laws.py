"""Contact laws in series with a layer (a linear spring, a Greenwood-Williamson asperity layer):
force against the closed-form overlap, tangent stiffness against the series formula, limits,
derivatives against finite differences, and a driven chain's linear resonance with them."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain import laws
from hertzchain.driven import DrivenChain, lockin_grid
from hertzchain.driven.linear import normal_modes

KAPPA = 1.38e10  # N/m^1.5, a 19 mm steel bead on a steel flat
FORCES = np.geomspace(1e-6, 50.0, 40)  # N


def hertz_overlap(force):
    return (force / KAPPA) ** (2.0 / 3.0)


def hertz_stiffness(force):
    return 1.5 * KAPPA ** (2.0 / 3.0) * force ** (1.0 / 3.0)


def constants(kappa=KAPPA):
    return laws.ContactConstants(jnp.asarray(kappa))


@eqx.filter_jit
def evaluate(law, overlap_m, force_n, kappa=KAPPA):
    """The law's force at `overlap_m`, its overlap and tangent stiffness at `force_n`, and
    dE/d(delta) at `overlap_m`, in one compiled call."""
    c = constants(kappa)
    grad_energy = jax.vmap(jax.grad(lambda d: law.energy(d, d, c)))(overlap_m)
    return law.force(overlap_m, None, c), law.overlap_at_force(force_n, c), law.stiffness_at_force(force_n, c), \
        grad_energy


@pytest.mark.parametrize("spring_over_contact", [1e-6, 1.0, 1e6])
def test_series_spring_force_inverts_the_closed_form_overlap(spring_over_contact):
    # delta(F) = (F/kappa)^(2/3) + F/k_s in closed form: the law's force at that overlap is F
    # and its tangent stiffness the series formula, whichever element is the softer
    compliance = 1.0 / (spring_over_contact * hertz_stiffness(1.0))
    law = laws.SeriesCompliance(laws.Hertz(), compliance)
    overlap = hertz_overlap(FORCES) + compliance * FORCES
    force, at_force, stiffness, grad_energy = evaluate(law, jnp.asarray(overlap), jnp.asarray(FORCES))
    np.testing.assert_allclose(np.asarray(at_force), overlap, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(force), FORCES, rtol=1e-13)
    series = 1.0 / (1.0 / hertz_stiffness(FORCES) + compliance)
    np.testing.assert_allclose(np.asarray(stiffness), series, rtol=1e-12)
    # the stored energy is the force's integral: dE/d(delta) = F
    np.testing.assert_allclose(np.asarray(grad_energy), FORCES, rtol=1e-11)


def test_series_spring_limits_and_open_contact():
    overlap = jnp.asarray(hertz_overlap(FORCES))
    stiff = laws.SeriesCompliance(laws.Hertz(), 1e-18)  # k_s = 1e18 N/m: Hertz's force
    np.testing.assert_allclose(np.asarray(evaluate(stiff, overlap, overlap)[0]), FORCES, rtol=1e-7)
    soft = 10.0  # m/N, k_s = 0.1 N/m, 1e5 times below the contact's at these loads: F -> delta/c
    np.testing.assert_allclose(np.asarray(evaluate(laws.SeriesCompliance(laws.Hertz(), soft), overlap, overlap)[0]),
                               np.asarray(overlap) / soft, rtol=2e-4)
    law = laws.SeriesCompliance(laws.Hertz(), 1e-8)
    apart = jnp.asarray([-1e-9, 0.0])
    force, _, _, slope = evaluate(law, apart, apart)  # dE/d(delta) = F: 0, and so its slope
    np.testing.assert_array_equal(np.asarray(force), 0.0)
    np.testing.assert_array_equal(np.asarray(slope), 0.0)
    with pytest.raises(ValueError, match="no history"):
        laws.SeriesCompliance(laws.Thornton(), 1e-9)
    with pytest.raises(ValueError, match="compliance_m_n"):
        laws.SeriesCompliance(laws.Hertz(), -1.0)


def test_series_force_derivatives_match_finite_differences():
    # the one differentiated Newton step at the root: the implicit function's derivative
    overlap = 40e-9

    def force(theta):
        kappa, compliance = theta
        return laws.SeriesCompliance(laws.Hertz(), compliance).force(overlap, None, laws.ContactConstants(kappa))

    force = jax.jit(force)
    theta = jnp.asarray([KAPPA, 2e-9])
    grad = np.asarray(jax.grad(force)(theta))
    forward = np.asarray(jax.jacfwd(force)(theta))
    for i in range(2):
        step = 1e-6 * float(theta[i])
        fd = (float(force(theta.at[i].add(step))) - float(force(theta.at[i].add(-step)))) / (2 * step)
        assert grad[i] == pytest.approx(fd, rel=1e-7)
        assert forward[i] == pytest.approx(fd, rel=1e-7)


def test_rough_contact_matches_greenwood_williamson_in_series_and_tends_to_hertz():
    roughness, touch = 8e-9, 0.05  # m, N
    law = laws.RoughContact(laws.Hertz(), roughness, touch)
    overlap = hertz_overlap(FORCES) + roughness * np.log1p(FORCES / touch)
    force, at_force, stiffness, grad_energy = evaluate(law, jnp.asarray(overlap), jnp.asarray(FORCES))
    np.testing.assert_allclose(np.asarray(force), FORCES, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(at_force), overlap, rtol=1e-15)
    series = 1.0 / (1.0 / hertz_stiffness(FORCES) + roughness / (touch + FORCES))
    np.testing.assert_allclose(np.asarray(stiffness), series, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(grad_energy), FORCES, rtol=1e-11)
    # the layer alone (an infinitely stiff bulk): F = F_t (exp(delta/sigma) - 1)
    layer = jnp.asarray(np.linspace(0.0, 6.0, 40) * roughness)
    np.testing.assert_allclose(np.asarray(evaluate(law, layer, layer, kappa=1e30)[0]),
                               touch * np.expm1(np.asarray(layer) / roughness), rtol=1e-9)
    # sigma -> 0: the bulk law's force
    hertz = hertz_overlap(FORCES)
    smooth = laws.RoughContact(laws.Hertz(), 1e-16, touch)
    loaded = FORCES > 1e-3
    np.testing.assert_allclose(np.asarray(evaluate(smooth, jnp.asarray(hertz), jnp.asarray(hertz))[0])[loaded],
                               FORCES[loaded], rtol=1e-6)
    with pytest.raises(ValueError, match="roughness_m"):
        laws.RoughContact(laws.Hertz(), 0.0, touch)


def test_driven_chain_resonance_with_a_spring_at_the_driver_only():
    # a bead between a driver (Hertz in series with a cap spring) and a wall (Hertz): the
    # linear resonance is sqrt((k_0 + k_1)/m)/(2 pi) with k_0 the series formula
    mass, force, cap = 0.028, 4.5, 1.0 / 2e7  # kg, N, m/N (a 2e7 N/m cap)
    chain = DrivenChain([mass], [KAPPA, KAPPA], force, 0.0,
                        contact_law=laws.SeriesCompliance(laws.Hertz(), jnp.asarray([cap, 0.0])))
    k_hertz = hertz_stiffness(force)
    k0 = 1.0 / (1.0 / k_hertz + cap)
    frequency, _ = normal_modes(chain)
    assert float(frequency[0]) == pytest.approx(np.sqrt((k0 + k_hertz) / mass) / (2 * np.pi), rel=1e-12)
    np.testing.assert_allclose(np.asarray(chain.static_overlap_m()),
                               [hertz_overlap(force) + cap * force, hertz_overlap(force)], rtol=1e-14)
    with pytest.raises(ValueError, match="one per contact"):
        DrivenChain([mass], [KAPPA, KAPPA], force, 0.0, contact_law=laws.SeriesCompliance(laws.Hertz(), [cap] * 3))


@pytest.mark.slow
def test_driven_bead_with_a_cap_spring_responds_linearly_on_the_jax_kernel():
    mass, force, cap = 0.028, 4.5, 1.0 / 2e7  # kg, N, m/N
    k_hertz = hertz_stiffness(force)
    k0 = 1.0 / (1.0 / k_hertz + cap)
    # the JAX kernel runs it (the fused one has Hertz only) and says so; at a small drive the
    # lock-in is the linear response's
    f_res = np.sqrt((k0 + k_hertz) / mass) / (2 * np.pi)
    damped = DrivenChain([mass], [KAPPA, KAPPA], force, 2000.0,
                         contact_law=laws.SeriesCompliance(laws.Hertz(), jnp.asarray([cap, 0.0])))
    grid = lockin_grid(damped, [f_res], [1e-10], harmonics=(1.0,), ramp_periods=10, hold_periods=30, window_periods=4,
                       steps_per_period=32)
    assert grid.kernel == "jax" and not damped.runs_on_fused_kernel
    w = 2 * np.pi * f_res
    linear = k0 * 1e-10 / np.abs(k0 + k_hertz - mass * w**2 + 1j * w * mass * 2000.0) * w / np.sqrt(2.0)
    assert float(grid.rms[0, 0, 0]) == pytest.approx(linear, rel=5e-3)


@pytest.mark.slow
def test_series_layers_run_in_impact_chains_with_closed_energy_books():
    import hertzchain as hc

    hertz = hc.simulate(hc.ChainSetup(3))
    for law in (laws.SeriesCompliance(laws.Hertz(), 1e-8), laws.RoughContact(laws.Hertz(), 5e-8, 0.5)):
        traces = hc.simulate(hc.ChainSetup(3, contact_law=law))
        error = np.max(np.abs(np.asarray(traces.energy_error_j))) / float(traces.initial_energy_j)
        assert error < 1e-4  # the layer's stored energy is in the books
        if isinstance(law, laws.SeriesCompliance):  # a 1e8 N/m spring in every contact: a far lower peak
            assert float(np.max(np.asarray(traces.max_force_n))) < 0.8 * float(np.max(np.asarray(hertz.max_force_n)))
