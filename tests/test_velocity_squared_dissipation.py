"""Velocity-squared contact dissipation (`laws.VelocitySquared`) in a binary collision:
the energy the chain loses against an independent integration of the collision's ODE and
against the first-order closed form $\\Delta E = \\tfrac{10}{7}c\\,v^2\\delta_m$."""

import numpy as np
import pytest
from helpers import binary_collision_loss_j

import hertzchain as hc
from hertzchain import laws
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
from hertzchain.timegrid import choose_time_grid

C_N_S2_M2 = 20.0  # takes 0.7 % (0.1 m/s) and 1.6 % (0.3 m/s) of a collision's energy between 13 mm steel beads
SPEEDS_M_S = (0.1, 0.3)


def test_velocity_squared_loss_in_a_binary_collision():
    setup = hc.ChainSetup(1, end="free", dissipation=laws.VelocitySquared(C_N_S2_M2))
    mass, kappa = float(setup.bead_mass_kg[0]), float(setup.contact_kappa()[0])
    batched, _ = hc.batch_setup(setup, striker_velocity_m_s=list(SPEEDS_M_S))
    # the force jumps to c v^2 at contact onset (as a dashpot's does): an error of order
    # dt / t_c: 0.3 % at the default 200 steps per contact, 0.1 % at 800
    grid = choose_time_grid(batched, t_end_s=3e-4, sample_interval_s=1e-6, steps_per_contact=800)
    run = solve_batched(batched, grid, Recording(contacts=(0,)))
    assert run.kernel == "native full (host)"  # the law in the native kernels' rate slot (`laws.registry`)
    for k, speed in enumerate(SPEEDS_M_S):
        expected = binary_collision_loss_j(mass, kappa, lambda d, rate: C_N_S2_M2 * abs(rate) * rate, speed)
        assert float(run.dissipated_j[k]) == pytest.approx(expected, rel=2e-3)
        # first order in c: c times the integral of |rate|^3 along the elastic collision
        largest = (5.0 * (mass / 2.0) * speed**2 / (4.0 * kappa)) ** 0.4
        weak = 10.0 / 7.0 * C_N_S2_M2 * speed**2 * largest
        assert expected == pytest.approx(weak, rel=3.0 * expected / (0.25 * mass * speed**2))
    # the books balance: what the law took is what the motion lost
    assert np.all(np.abs(np.asarray(run.energy_error_j)) < 1e-5 * 0.25 * mass * np.asarray(SPEEDS_M_S) ** 2)


def test_velocity_squared_force_and_its_registry_entry():
    law = laws.VelocitySquared(C_N_S2_M2)
    rates = np.array([-0.2, 0.0, 0.3])
    np.testing.assert_allclose(law.force(1e-6, rates, 1e10), C_N_S2_M2 * np.abs(rates) * rates, rtol=1e-15)
    assert law.native_name == "velocity_squared" and laws.registry.runs_natively(laws.Hertz(), (law,))
    with pytest.raises(ValueError, match="VelocitySquared: c_n_s2_m2 must be finite and >= 0"):
        laws.VelocitySquared(-1.0)
