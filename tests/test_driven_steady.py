"""Steady-state detection: windows until successive lock-ins agree."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import linear_response, lydon_bead

from hertzchain.driven import lockin_grid
from hertzchain.driven.steady import lockin_until_steady


def test_stops_when_settled_and_reads_the_steady_response():
    frequencies = np.array([4000.0, 5000.0, 6000.0])
    amplitude = 1e-12  # linear regime: the closed form holds
    results = {}
    for gamma in (3000.0, 1000.0):
        chain = lydon_bead(damping_rate_per_s=gamma)
        steady = lockin_until_steady(chain, frequencies, [amplitude], rtol=1e-6, harmonics=(1.0,), ramp_periods=10,
                                     window_periods=2, max_windows=200, steps_per_period=400)
        assert bool(np.all(steady.converged))
        exact = linear_response(chain, frequencies)[0] * amplitude
        got = np.asarray(steady.complex_amplitude[0, :, 0])
        # Verlet at 400 steps a period: resonance shifted by (2 pi / 400)^2 / 24 = 1e-5 (Q ~ 5-16)
        np.testing.assert_allclose(got, exact, rtol=5e-4)
        results[gamma] = steady
    # a transient decays as exp(-gamma t / 2): a third of the damping needs more windows
    assert int(results[1000.0].periods_run) > 2 * int(results[3000.0].periods_run)
    # and the runs read what a fixed hold of the same length reads
    chain = lydon_bead(damping_rate_per_s=1000.0)
    held = lockin_grid(chain, frequencies, [amplitude], harmonics=(1.0,), ramp_periods=10,
                       hold_periods=int(results[1000.0].periods_run), window_periods=2, steps_per_period=400)
    np.testing.assert_allclose(np.asarray(results[1000.0].complex_amplitude), np.asarray(held.complex_amplitude),
                               rtol=1e-10)


def test_reports_runs_that_never_settle():
    chain = lydon_bead(damping_rate_per_s=50.0)  # Q ~ 600: far from steady after 6 windows
    steady = lockin_until_steady(chain, [5000.0], [1e-12], rtol=1e-8, harmonics=(1.0,), ramp_periods=2,
                                 window_periods=2, max_windows=6, steps_per_period=64)
    assert not bool(steady.converged[0, 0])
    assert int(steady.windows[0, 0]) == 7 and int(steady.periods_run) == 12


@pytest.mark.slow  # 25 s on two loaded cores: `pytest -m slow tests/test_driven_steady.py`
def test_forward_derivative_through_the_stopping_loop():
    chain = lydon_bead(damping_rate_per_s=3000.0)

    def rms(amplitude):
        return lockin_until_steady(chain, [5000.0], amplitude, rtol=1e-6, harmonics=(1.0,), ramp_periods=5,
                                   window_periods=2, max_windows=100, steps_per_period=64).rms[0, 0, 0]

    amplitude = jnp.array([1e-12])
    slope = jax.jacfwd(rms)(amplitude)[0]
    # linear regime: the RMS is proportional to the drive
    assert abs(float(slope) * 1e-12 / float(rms(amplitude)) - 1) < 1e-6
