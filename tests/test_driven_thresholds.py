"""Period-doubling thresholds by continuation: the multiplier crosses -1 there (eigenvalues of
the monodromy, another code path), the f/2 lock-in of a time-stepped run appears there, and the
threshold's derivative by the implicit function theorem matches finite differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain import laws
from hertzchain.driven import DrivenChain, HarmonicSchedule, floquet_multipliers, lockin_schedule
from hertzchain.driven.floquet import period_doubling_threshold
from hertzchain.driven.thresholds import onset_tangents, period_doubling_onsets


def fitted_bead():
    """The single bead of the bending fit: F0 = 0.138 N, resonance 3982 Hz, zeta = 0.035."""
    kappa = 3.8016e10
    return DrivenChain([0.028], [kappa, kappa], 0.137979, 1751.8)


FREQUENCIES = [7600.0, 7900.0, 6000.0]


def onsets(chain):
    return period_doubling_onsets(chain, FREQUENCIES, lowest_amplitude_m=5e-9, highest_amplitude_m=100e-9)


@pytest.mark.slow  # ~15 s: the compilation of the nested forward passes
def test_onset_matches_the_independent_model():
    found = onsets(fitted_bead())
    assert list(found.found) == [True, True, False]
    assert found.reasons[2] == "no period doubling up to 1e-07 m"  # 6 kHz is not near twice the resonance
    # the research notes' independent NumPy model: 12.3 nm at 7900 Hz for these constants
    assert found.amplitude_m[1] == pytest.approx(12.3e-9, rel=0.01)


@pytest.mark.slow
def test_onset_is_where_a_real_multiplier_crosses_minus_one():
    chain = fitted_bead()
    a = onsets(chain).amplitude_m[:2]
    floquet = floquet_multipliers(chain, np.repeat(FREQUENCIES[:2], 2), np.stack([a * 0.998, a * 1.002], 1).ravel(),
                                  steps_per_period=48, unroll=1)
    below, above = floquet.most_negative_real.reshape(2, 2).T
    assert np.all(below > -1.0) and np.all(above < -1.0)
    assert np.all(np.abs(below + 1.0) < 2e-3) and np.all(np.abs(above + 1.0) < 2e-3)


@pytest.mark.slow
def test_f2_lockin_of_a_stepped_run_appears_at_the_onset():
    chain = fitted_bead()
    found = onsets(chain)
    a = found.amplitude_m[1]
    # nothing seeds f/2 but rounding (~1e-16), which the multiplier (about -1.07 at 1.6 a*) grows
    # by ~7 % a period: 800 periods a level
    schedule = HarmonicSchedule.levels(FREQUENCIES[1], np.array([0.9 * a, 1.6 * a]), steps_per_period=48,
                                       ramp_periods=25, periods_per_level=800)
    rms = np.asarray(lockin_schedule(chain, schedule, harmonics=(1.0, 0.5), window_periods=4).rms)[:, :, 0]
    ratio = rms[1] / rms[0]  # f/2 over the fundamental, below (0.9 a*) and above (1.6 a*) the threshold
    assert ratio[0] < 1e-3 and ratio[1] > 0.05


@pytest.mark.slow
def test_onset_derivative_matches_finite_differences():
    chain = fitted_bead()
    found = onsets(chain)

    def build(log_factors):  # the precompression and both contacts' constants, scaled
        scaled = eqx.tree_at(lambda c: c.precompression_n, chain, chain.precompression_n * jnp.exp(log_factors[0]))
        return eqx.tree_at(lambda c: c.contact_kappa_n_m1p5, scaled,
                           chain.contact_kappa_n_m1p5 * jnp.exp(log_factors[1]))

    x = jnp.zeros(2)
    tangents = jax.vmap(lambda d: jax.jvp(build, (x,), (d,))[1])(jnp.eye(2))
    derivative = onset_tangents(chain, found, tangents)
    assert np.all(derivative[:, 2] == 0.0)  # not found: no derivative
    h = 1e-4
    for k in range(2):
        step = np.zeros(2)
        step[k] = h
        up, down = onsets(build(x + step)), onsets(build(x - step))
        difference = (up.amplitude_m[:2] - down.amplitude_m[:2]) / (2 * h)
        np.testing.assert_allclose(derivative[k, :2], difference, rtol=1e-5)


def test_search_bounds_are_checked():
    with pytest.raises(ValueError, match="lowest_amplitude_m"):
        period_doubling_onsets(fitted_bead(), [7900.0], lowest_amplitude_m=5e-8, highest_amplitude_m=1e-8)


@pytest.mark.slow
def test_emulated_loop_doubles_just_past_the_floquet_threshold():
    """Time stepping through the lab's loop (0.25 s a step) against the Floquet threshold: f/2 is
    absent at every step below it and present from the first step above it (the multiplier lifts
    rounding to the rule's level within the hold), and at 7900 Hz it ends where it began."""
    from hertzchain.driven.thresholds import emulate_loop

    chain = fitted_bead()
    threshold = onsets(chain).amplitude_m[1]
    up = np.arange(4.0, 25.1, 1.5) * 1e-9
    loop = emulate_loop(chain, FREQUENCIES[1], np.r_[up, up[-2::-1]])
    assert loop.onset_up_m == up[up > threshold][0]
    assert loop.gone_down_m == up[up < threshold][-1]


@pytest.mark.slow  # ~60 s (nested forward passes through 18 state coordinates); the default suite's
# micro-slip Floquet checks are in test_driven_floquet.py
def test_micro_slip_onset_and_its_derivative():
    """With micro-slip supports (the sliders as state): the continuation's threshold against a
    scan of `floquet_multipliers` from rest (eigenvalues, linear interpolation of mu + 1), and
    its derivative with respect to the supports' stiffness against central differences (the map
    is piecewise smooth: at 7900 Hz no slip pattern changes within the steps)."""
    base = eqx.tree_at(lambda c: c.support_friction, fitted_bead(), laws.IwanSupport(1e6, 10e-9, elements=8),
                       is_leaf=lambda leaf: leaf is None)

    def build(log_factor):
        return eqx.tree_at(lambda c: c.support_friction.stiffness_n_m, base,
                           base.support_friction.stiffness_n_m * jnp.exp(log_factor[0]))

    def search(chain):
        return period_doubling_onsets(chain, [7900.0], lowest_amplitude_m=5e-9, highest_amplitude_m=60e-9,
                                      steps_per_period=48)

    found = search(base)
    assert found.reasons == ("crossed",)
    scan = period_doubling_threshold(base, 7900.0, np.linspace(12e-9, 18e-9, 7), steps_per_period=48)
    assert found.amplitude_m[0] == pytest.approx(scan, rel=5e-3)  # measured 1.4268e-8 against 1.4288e-8 m
    x = jnp.zeros(1)
    tangents = jax.vmap(lambda d: jax.jvp(build, (x,), (d,))[1])(jnp.eye(1))
    derivative = onset_tangents(base, found, tangents)[0, 0]
    h = 1e-3
    difference = (search(build(x + h)).amplitude_m[0] - search(build(x - h)).amplitude_m[0]) / (2 * h)
    assert derivative > 0  # measured 2.63e-9 m per unit of log K
    assert derivative == pytest.approx(difference, rel=1e-5)  # measured 4e-6
