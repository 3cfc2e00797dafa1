"""The linearised driven chain with micro-slip supports: the supports' stiffness before
anything slips is part of the normal modes and the frequency response (closed forms of a
bead on three springs, two beads on five), and the time-stepped bead at a drive far below
slip follows that linear response."""

import numpy as np
import pytest

from hertzchain import laws
from hertzchain.driven import DrivenChain, lockin_grid
from hertzchain.driven.linear import frequency_response, normal_modes

MASS_KG = 0.028
KAPPA = 6.0e9  # N/m^1.5
PRELOAD_N = 4.5
SUPPORT_N_M = 3.0e6


def _hertz_stiffness(kappa, force_n):
    return 1.5 * kappa ** (2.0 / 3.0) * force_n ** (1.0 / 3.0)


def test_bead_on_three_springs_resonates_at_the_closed_form():
    chain = DrivenChain([MASS_KG], [KAPPA, 1.5 * KAPPA], PRELOAD_N, 300.0,
                        support_friction=laws.IwanSupport(SUPPORT_N_M, 40e-9))
    k0, k1 = _hertz_stiffness(KAPPA, PRELOAD_N), _hertz_stiffness(1.5 * KAPPA, PRELOAD_N)
    expected = np.sqrt((k0 + k1 + SUPPORT_N_M) / MASS_KG) / (2 * np.pi)
    assert float(normal_modes(chain)[0][0]) == pytest.approx(expected, rel=1e-12)
    # the supports move it by a measurable amount: sqrt(1 + Ks / (k0 + k1)) - 1
    bare = DrivenChain([MASS_KG], [KAPPA, 1.5 * KAPPA], PRELOAD_N, 300.0)
    assert float(normal_modes(chain)[0][0] / normal_modes(bare)[0][0]) == pytest.approx(
        np.sqrt(1 + SUPPORT_N_M / (k0 + k1)), rel=1e-12)
    # steady response: X = k0 / (k0 + k1 + Ks - m w^2 + i w m gamma)
    f = np.array([3000.0, 4200.0, 7000.0])
    w = 2 * np.pi * f
    closed = k0 / (k0 + k1 + SUPPORT_N_M - MASS_KG * w**2 + 1j * w * MASS_KG * 300.0)
    x, forces = frequency_response(chain, f)
    np.testing.assert_allclose(np.asarray(x[:, 0]), closed, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(forces[:, 1]), k1 * closed, rtol=1e-12)


def test_two_beads_each_held_by_its_own_supports():
    supports = np.array([2.0e6, 5.0e6])
    chain = DrivenChain([MASS_KG, 1.2 * MASS_KG], [KAPPA, KAPPA, KAPPA], PRELOAD_N, 0.0,
                        support_friction=laws.IwanSupport(supports, 40e-9))
    k = _hertz_stiffness(KAPPA, PRELOAD_N)
    m = np.array([MASS_KG, 1.2 * MASS_KG])
    # the 2x2 generalised eigenproblem in closed form
    a, d, b = (2 * k + supports[0]) / m[0], (2 * k + supports[1]) / m[1], k**2 / (m[0] * m[1])
    omega2 = 0.5 * (a + d) + np.array([-1.0, 1.0]) * np.sqrt(0.25 * (a - d) ** 2 + b)
    np.testing.assert_allclose(np.asarray(normal_modes(chain)[0]), np.sqrt(omega2) / (2 * np.pi), rtol=1e-12)


def test_stepped_bead_far_below_slip_follows_the_linear_response():
    """A 0.05 nm drive against 2 um of slip: every slider sticks to < 1e-4 of its range, so
    the lock-in must be the linear response with the supports' stiffness (and not without).
    The tolerance is the integrator's own at 128 steps a period: the bare bead's stepped
    response differs from its closed form by the same 1.2e-3 at 0.9 f0."""
    damping = 600.0
    chain = DrivenChain([MASS_KG], [KAPPA, KAPPA], PRELOAD_N, damping,
                        support_friction=laws.IwanSupport(4.0 * SUPPORT_N_M, 2e-6, elements=4))
    resonance = float(normal_modes(chain)[0][0])
    f = np.array([0.9, 1.0, 1.1]) * resonance
    drive = 5e-11
    grid = lockin_grid(chain, f, np.array([drive]), harmonics=(1.0,), ramp_periods=40, hold_periods=160,
                       window_periods=4, steps_per_period=128)
    stepped = np.asarray(grid.rms[0][:, 0])
    x, _ = frequency_response(chain, f)
    linear = np.abs(np.asarray(x[:, 0])) * 2 * np.pi * f * drive / np.sqrt(2)
    np.testing.assert_allclose(stepped, linear, rtol=2e-3)
    bare = DrivenChain([MASS_KG], [KAPPA, KAPPA], PRELOAD_N, damping)
    x_bare, _ = frequency_response(bare, f)
    without = np.abs(np.asarray(x_bare[:, 0])) * 2 * np.pi * f * drive / np.sqrt(2)
    assert np.max(np.abs(stepped / without - 1)) > 0.1
