"""Hunt-Crossley hysteretic damping (`laws.HuntCrossley`): its force against its published
form, a binary collision's loss against an independent integration of the collision's ODE and
against the first-order closed form $\\Delta E = \\alpha v\\cdot\\mu v^2$, and which kernel runs
it. Its trajectories in driven chains: `test_driven_laws.py`."""

import numpy as np
import pytest
from helpers import binary_collision_loss_j

import hertzchain as hc
from hertzchain import laws
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
from hertzchain.timegrid import choose_time_grid

ALPHA_S_M = 0.1  # restitution about 1 - alpha v: 0.99 at 0.1 m/s, 0.97 at 0.3 m/s
SPEEDS_M_S = (0.1, 0.3)


def test_hunt_crossley_force_and_its_registry_entry():
    law = laws.HuntCrossley(ALPHA_S_M)
    overlaps = np.array([-1e-6, 0.0, 2e-6, 5e-6])
    kappa, rate = 1.2e10, -0.3
    expected = 1.5 * ALPHA_S_M * kappa * np.maximum(overlaps, 0.0) ** 1.5 * rate
    np.testing.assert_allclose(law.force(overlaps, rate, kappa), expected, rtol=1e-14, atol=0.0)
    assert float(law.force(2e-6, rate, 0.0)) == 0.0  # a contact of no stiffness is none
    assert bool(law.is_active()) and not bool(laws.HuntCrossley().is_active())
    assert law.native_name is None and not laws.registry.runs_natively(laws.Hertz(), (law,))
    with pytest.raises(ValueError, match="HuntCrossley: alpha_s_m must be finite and >= 0"):
        laws.HuntCrossley(-1.0)


def test_hunt_crossley_loss_in_a_binary_collision():
    setup = hc.ChainSetup(1, end="free", dissipation=laws.HuntCrossley(ALPHA_S_M))
    mass, kappa = float(setup.bead_mass_kg[0]), float(setup.contact_kappa()[0])
    batched, _ = hc.batch_setup(setup, striker_velocity_m_s=list(SPEEDS_M_S))
    grid = choose_time_grid(batched, t_end_s=3e-4, sample_interval_s=1e-6)
    run = solve_batched(batched, grid, Recording(contacts=(0,)))
    assert run.kernel == "jax"  # no native kernel has the law (`laws.registry`)
    for k, speed in enumerate(SPEEDS_M_S):
        expected = binary_collision_loss_j(
            mass, kappa, lambda d, rate: 1.5 * ALPHA_S_M * kappa * d**1.5 * rate, speed)
        # the force is continuous at onset: velocity Verlet's error at 200 steps a contact is small
        assert float(run.dissipated_j[k]) == pytest.approx(expected, rel=1e-3)
        # first order in alpha: alpha v of the relative motion's energy mu v^2 / 2, twice
        weak = ALPHA_S_M * speed * (mass / 2.0) * speed**2
        assert expected == pytest.approx(weak, rel=2.0 * ALPHA_S_M * speed)
        assert abs(expected - weak) > 0.05 * ALPHA_S_M * speed * weak  # the second order is seen
    # the books balance: what the law took is what the motion lost
    assert np.all(np.abs(np.asarray(run.energy_error_j)) < 1e-5 * 0.25 * mass * np.asarray(SPEEDS_M_S) ** 2)
