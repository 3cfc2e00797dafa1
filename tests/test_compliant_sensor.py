"""Embedded sensors in compliance form: the split-bead mechanics in other coordinates, exact
against the split-bead model, the rigid chain at f0 = inf, and differentiable there."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain.chain import ChainSetup, build_model
from hertzchain.compliant_sensor import CompliantSensors, with_compliant_sensors
from hertzchain.integrate import Recording, solve
from hertzchain.timegrid import TimeGrid, choose_time_grid

N, BEADS, BETA, F0 = 8, (3, 5), 0.11, 85e3
RECORD = Recording(contacts=(2, 3, 4, 5))


@pytest.mark.parametrize("changes", [{}, {"precompression_n": 2.0}], ids=["bare", "preload"])
def test_matches_the_split_bead_model(changes):
    split = ChainSetup(N, striker_velocity_m_s=0.3, sensor_beads=BEADS, sensor_beta=BETA, sensor_f0_hz=F0, **changes)
    grid = choose_time_grid(split, t_end_s=0.5e-3, sample_interval_s=1e-6)
    reference = solve(split, grid, RECORD)
    compliant = solve(ChainSetup(N, striker_velocity_m_s=0.3, **changes), grid, RECORD,
                      compliant_sensors=CompliantSensors.from_f0(BEADS, beta=BETA, f0_hz=F0))
    peak = float(jnp.max(reference.forces_n["wall"]))
    for name in ("contact_2", "contact_3", "contact_4", "contact_5", "wall"):
        np.testing.assert_allclose(compliant.forces_n[name], reference.forces_n[name], atol=1e-11 * peak)
    # The soft sensors change the chain itself: the wall force differs from a rigid chain's.
    rigid = solve(ChainSetup(N, striker_velocity_m_s=0.3, **changes), grid, RECORD)
    assert float(jnp.max(jnp.abs(rigid.forces_n["wall"] - reference.forces_n["wall"]))) > 1e-3 * peak
    # The ledger books the sensors' spring and internal kinetic energy: the same as the split model's.
    np.testing.assert_allclose(compliant.energy_error_j, reference.energy_error_j,
                               atol=1e-6 * float(reference.initial_energy_j))
    assert float(jnp.max(jnp.abs(compliant.energy_error_j))) < 1e-6 * float(compliant.initial_energy_j)


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; the split-bead comparison of this file stays in the default suite
def test_rigid_sensors_are_the_base_chain_and_differentiable_there():
    setup = ChainSetup(N, striker_velocity_m_s=0.2)
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=400)
    base = solve(setup, grid, RECORD)
    rigid = solve(setup, grid, RECORD, compliant_sensors=CompliantSensors(BEADS, BETA, 0.0))
    for name in base.forces_n:
        np.testing.assert_array_equal(rigid.forces_n[name], base.forces_n[name])

    def wall(inv_omega0_sq_s2, beta):
        sensors = CompliantSensors(BEADS, beta, inv_omega0_sq_s2)
        return solve(setup, grid, RECORD, compliant_sensors=sensors).forces_n["wall"]

    # At 1/omega0^2 = 0 (rigid) and at a resolved f0 the derivative matches central differences.
    for inv in (0.0, 1.0 / (2 * np.pi * F0) ** 2):
        d_inv = jax.jacfwd(wall)(inv, BETA)
        step = 2e-3 / (2 * np.pi * F0) ** 2
        central = (wall(inv + step, BETA) - wall(max(inv - step, 0.0), BETA)) / (inv + step - max(inv - step, 0.0))
        assert bool(jnp.all(jnp.isfinite(d_inv)))
        scale = float(jnp.max(jnp.abs(central)))
        assert scale > 0
        np.testing.assert_allclose(d_inv, central, atol=2e-3 * scale)


def test_unresolved_resonance_is_quasi_static_and_close_to_rigid():
    """omega0 dt > 1: the sensor force follows its drive; a 2 MHz sensor barely changes the chain."""
    setup = ChainSetup(N, striker_velocity_m_s=0.3)
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=400)
    base = solve(setup, grid, RECORD)
    stiff = solve(setup, grid, RECORD, compliant_sensors=CompliantSensors.from_f0(BEADS, beta=BETA, f0_hz=2e6))
    peak = float(jnp.max(base.forces_n["wall"]))
    difference = float(jnp.max(jnp.abs(stiff.forces_n["wall"] - base.forces_n["wall"])))
    assert 0 < difference < 5e-3 * peak


def test_bad_sensor_beads_are_refused():
    model = build_model(ChainSetup(N))
    with pytest.raises(ValueError, match="no contact on both sides"):
        with_compliant_sensors(model, (N,), beta=BETA, inv_omega0_sq_s2=1e-12)
    with pytest.raises(ValueError, match="lists a bead twice"):
        with_compliant_sensors(model, (2, 2), beta=BETA, inv_omega0_sq_s2=1e-12)
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=10)
    with pytest.raises(ValueError, match="already splits sensor beads"):
        solve(ChainSetup(N, sensor_beads=(3,)), grid, RECORD, compliant_sensors=CompliantSensors((2,), BETA, 1e-12))
