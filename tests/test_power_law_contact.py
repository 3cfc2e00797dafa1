"""Power-law contacts F = kappa delta_r^{3/2} (delta/delta_r)^n: Hertz at n = 3/2, the
binary-collision time's velocity scaling v^{(1-n)/(n+1)}, energy conservation, and the
diffrax reference."""

import numpy as np
import pytest

import hertzchain as hc
from hertzchain.reference import simulate_reference


def _collision_time_s(velocity, exponent):
    setup = hc.ChainSetup(1, end="free", striker_velocity_m_s=velocity, contact_exponent=exponent)
    run = hc.simulate(setup, t_end_s=0.2e-3, sample_interval_s=5e-9, contacts=(0,), on_yield="ignore")
    force = np.asarray(run.forces_n["contact_0"])
    return 5e-9 * np.count_nonzero(force > 0)


def test_hertz_is_the_power_law_at_three_halves():
    plain = hc.simulate(hc.ChainSetup(6), t_end_s=0.3e-3)
    power = hc.simulate(hc.ChainSetup(6, contact_exponent=1.5, power_law=True), t_end_s=0.3e-3)
    np.testing.assert_allclose(power.forces_n["wall"], plain.forces_n["wall"], rtol=0, atol=1e-9)


@pytest.mark.parametrize("exponent", [1.3, 1.8])
def test_collision_time_scales_with_velocity_as_the_power_law_says(exponent):
    ratio = _collision_time_s(0.2, exponent) / _collision_time_s(0.05, exponent)
    assert ratio == pytest.approx(4.0 ** ((1 - exponent) / (1 + exponent)), rel=2e-3)


def test_power_law_chain_conserves_energy_and_agrees_with_the_reference():
    setup = hc.ChainSetup(6, contact_exponent=1.6, striker_velocity_m_s=0.2, precompression_n=1.0)
    verlet = hc.simulate(setup, t_end_s=0.4e-3, sample_interval_s=0.5e-6, contacts=(3,), steps_per_contact=800)
    assert float(np.max(np.abs(verlet.energy_error_j))) < 1e-5 * float(verlet.initial_energy_j)
    reference = simulate_reference(setup, t_end_s=0.4e-3, sample_interval_s=0.5e-6, contacts=(3,))
    for name in ("contact_3", "wall"):
        a, b = np.asarray(verlet.forces_n[name]), np.asarray(reference.forces_n[name])
        assert np.max(np.abs(a - b)) < 1e-3 * np.max(b)
    with pytest.raises(ValueError, match="cannot be combined"):
        hc.ChainSetup(3, contact_exponent=1.6, plasticity=True)
