"""Floquet multipliers: closed forms for linear oscillators, finite differences for a Hertz
orbit, and the period-doubling threshold against the research notes' independent model; with
micro-slip supports, the stuck sliders' neutral multipliers, finite differences where sliders
slip, and the threshold against the f/2 onset of runs stepped in time."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import linear_mode_frequencies_hz, lydon_bead, lydon_fitted_bead, uneven_chain
from scipy.linalg import expm

from hertzchain import laws
from hertzchain.driven import HarmonicSchedule, lockin_schedule
from hertzchain.driven.floquet import floquet_multipliers, period_doubling_threshold, period_map
from hertzchain.driven.measurements import subharmonic_present


def test_multipliers_of_a_damped_linear_oscillator_in_closed_form():
    chain = lydon_bead(damping_rate_per_s=1800.0)
    gamma = 1800.0
    omega0 = 2 * np.pi * linear_mode_frequencies_hz(chain)[0]
    omega_d = np.sqrt(omega0**2 - gamma**2 / 4)
    frequencies = np.array([3000.0, 5000.0, 9000.0])
    # amplitude 0: the orbit is the static state, the map the linearised chain's
    floquet = floquet_multipliers(chain, frequencies, 0.0, steps_per_period=1000, ramp_periods=0, hold_periods=1,
                                  newton_steps=0)
    period = 1 / frequencies
    exact = np.exp((-gamma / 2 + 1j * omega_d) * period)
    got = floquet.multipliers
    np.testing.assert_allclose(np.abs(got), np.broadcast_to(np.abs(exact)[:, None], got.shape), rtol=1e-5)
    np.testing.assert_allclose(np.sort(np.angle(got), axis=1), np.sort(np.stack([-np.angle(exact), np.angle(exact)], 1), axis=1),
                               atol=1e-4)  # Verlet's phase error per period: 2 pi (omega0 dt)^2 / 24 < 3e-5 here


def test_multipliers_of_a_linearised_chain_match_the_matrix_exponential():
    chain = uneven_chain()
    k = np.asarray(chain.contact_stiffness_n_m())
    m = np.asarray(chain.bead_mass_kg)
    gamma = np.asarray(chain.damping_rate_per_s)
    stiffness = np.diag(k[:-1] + k[1:]) - np.diag(k[1:-1], 1) - np.diag(k[1:-1], -1)
    system = np.block([[np.zeros((3, 3)), np.eye(3)], [-stiffness / m[:, None], -np.diag(gamma)]])
    frequency = 2100.0
    exact = np.linalg.eigvals(expm(system / frequency))
    ratio = linear_mode_frequencies_hz(chain)[-1] / frequency
    steps = int(np.ceil(1000 * ratio))
    # Verlet's phase error per drive period for the highest mode: 2 pi ratio (2 pi / 1000)^2 / 24
    bound = 2 * np.pi * ratio * (2 * np.pi / 1000) ** 2 / 24
    floquet = floquet_multipliers(chain, [frequency], [0.0], steps_per_period=steps, ramp_periods=0, hold_periods=1,
                                  newton_steps=0)
    got = floquet.multipliers[0]
    for value in exact:
        assert np.min(np.abs(got - value)) < 2 * bound * np.abs(value)


def test_monodromy_matches_finite_differences_on_a_hertz_orbit():
    chain = lydon_fitted_bead()
    floquet = floquet_multipliers(chain, [7900.0], [20e-9], steps_per_period=64)
    assert floquet.orbit_residual[0] < 1e-10
    advance = jax.jit(period_map(chain, jnp.asarray([7900.0]), jnp.asarray([20e-9]), 64))
    z = floquet.orbit_state[0]
    scale = np.array([1e-12, 1e-7])  # m, m/s
    columns = []
    for i in range(2):
        step = np.zeros(2)
        step[i] = scale[i]
        up = np.asarray(advance(jnp.asarray(z + step)[:, None]))[:, 0]
        down = np.asarray(advance(jnp.asarray(z - step)[:, None]))[:, 0]
        columns.append((up - down) / (2 * scale[i]))
    np.testing.assert_allclose(floquet.monodromy[0], np.stack(columns, 1), rtol=1e-6, atol=1e-9)
    # the orbit is a fixed point of the map
    np.testing.assert_allclose(np.asarray(advance(jnp.asarray(z)[:, None]))[:, 0], z, rtol=1e-9,
                               atol=1e-9 * np.abs(z).max())
    # past the threshold: a real multiplier below -1 (period doubling)
    assert floquet.most_negative_real[0] < -1.0


def test_period_doubling_tongue_tip_matches_the_independent_model():
    # research notes (real-data.md): the fitted single-bead model's tongue tip is 12 nm at 7.9 kHz
    chain = lydon_fitted_bead()
    amplitudes = np.linspace(2e-9, 40e-9, 20)
    at_tip = period_doubling_threshold(chain, 7900.0, amplitudes)
    assert at_tip == pytest.approx(12e-9, abs=0.5e-9)  # the notes quote two digits
    # and the tongue's edge rises away from the tip
    for frequency in (7000.0, 8300.0):
        assert period_doubling_threshold(chain, frequency, amplitudes) > 1.3 * at_tip
    # below every threshold the orbit is stable, with no multiplier beyond -1
    below = floquet_multipliers(chain, [7900.0], [0.8 * at_tip])
    assert below.largest_modulus[0] < 1.0



def micro_slip_bead(stiffness_n_m=1e6, slip_displacement_m=10e-9, elements=8):
    """`lydon_fitted_bead` on micro-slip supports (`laws.IwanSupport`)."""
    return eqx.tree_at(lambda c: c.support_friction, lydon_fitted_bead(),
                       laws.IwanSupport(stiffness_n_m, slip_displacement_m, elements=elements),
                       is_leaf=lambda leaf: leaf is None)


def test_supports_that_never_slip_are_a_linear_spring_with_neutral_sliders():
    # a slip displacement of 1 m: the sliders stick, the supports are a spring K in parallel
    # with the two contacts, omega_0^2 = (2 k_c + K) / m, and each stuck slider adds a
    # multiplier of exactly 1 that is not an instability
    stiffness, gamma = 2e6, float(lydon_fitted_bead().damping_rate_per_s[0])
    chain = micro_slip_bead(stiffness, 1.0, elements=4)
    contact = float(chain.contact_stiffness_n_m()[0])
    omega0 = np.sqrt((2 * contact + stiffness) / 0.028)
    omega_d = np.sqrt(omega0**2 - gamma**2 / 4)
    frequencies = np.array([3000.0, 7900.0])
    floquet = floquet_multipliers(chain, frequencies, 0.0, steps_per_period=1000, ramp_periods=0, hold_periods=1,
                                  newton_steps=1)
    exact = np.exp((-gamma / 2 + 1j * omega_d) / frequencies)
    assert floquet.multipliers.shape == (2, 2 + 4)
    assert floquet.stuck_sliders.all() and floquet.neutral[:, 2:].all() and not floquet.neutral[:, :2].any()
    assert np.all(floquet.multipliers[:, 2:] == 1.0)
    got = floquet.multipliers[:, :2]
    np.testing.assert_allclose(np.abs(got), np.broadcast_to(np.abs(exact)[:, None], got.shape), rtol=1e-5)
    np.testing.assert_allclose(np.sort(np.abs(np.angle(got)), axis=1), np.abs(np.angle(exact))[:, None] + 0 * got.real,
                               atol=2e-4)  # Verlet's phase error per period, 2 pi (omega0 dt)^2 / 24 < 1.1e-4 here
    np.testing.assert_allclose(floquet.largest_modulus, np.abs(exact), rtol=1e-5)  # the 1s are left out
    # the same at a drive amplitude that moves the bead (2 nm): the stuck sliders stay neutral
    moved = floquet_multipliers(chain, [3000.0], [2e-9], steps_per_period=64)
    assert moved.orbit_residual[0] < 1e-10 and moved.neutral[0, 2:].all() and moved.largest_modulus[0] < 1.0


def test_monodromy_with_slipping_sliders_matches_finite_differences():
    chain = micro_slip_bead()
    floquet = floquet_multipliers(chain, [7900.0], [12e-9], steps_per_period=48)
    assert floquet.orbit_residual[0] < 1e-10
    slipping = np.flatnonzero(~floquet.stuck_sliders[0, :, 0])
    assert 0 < slipping.size < 8  # some sliders slip, the others stick
    advance = jax.jit(period_map(chain, jnp.asarray([7900.0]), jnp.asarray([12e-9]), 48))
    z = floquet.orbit_state[0]
    # the bead's displacement and velocity, a slipping slider and a stuck one
    for column, scale in ((0, 1e-13), (1, 1e-9), (2 + slipping[0], 1e-13), (2 + 7, 1e-13)):
        step = np.zeros(z.size)
        step[column] = scale
        up = np.asarray(advance(jnp.asarray(z + step)[:, None]))[:, 0]
        down = np.asarray(advance(jnp.asarray(z - step)[:, None]))[:, 0]
        np.testing.assert_allclose(floquet.monodromy[0][:, column], (up - down) / (2 * scale), rtol=1e-5,
                                   atol=1e-7 * np.abs(floquet.monodromy[0][:, column]).max())
    # a slider that slips forgets where it was: its multiplier direction decays within a period
    k = int((~floquet.neutral[0]).sum())
    assert k == 2 + slipping.size and np.sort(np.abs(floquet.multipliers[0, :k]))[:slipping.size].max() < 1e-6


@pytest.mark.slow  # default-suite time on 2 cores; the multipliers against finite differences and the independent model's tongue tip stay in the default suite
def test_micro_slip_doubling_threshold_matches_stepped_lockin_onset():
    # the Floquet threshold (a real multiplier of the dynamics crossing -1) against the lab's
    # reading of runs stepped in time: f/2 above 0.1 x the fundamental at the end of a level
    chain = micro_slip_bead()
    amplitudes = np.linspace(12e-9, 18e-9, 7)  # 1 nm steps
    threshold = period_doubling_threshold(chain, 7900.0, amplitudes, steps_per_period=48)
    # the runs' f/2 grows from rounding (~1e-16) by |mu| a period: 1500 periods lift it to the
    # rule where |mu| > 1 + 35 / 1500, within one step above the threshold here
    schedule = HarmonicSchedule.levels(7900.0, amplitudes[None, :], steps_per_period=48, ramp_periods=25,
                                       periods_per_level=1500)
    rms = np.asarray(lockin_schedule(chain, schedule, harmonics=(1.0, 0.5), window_periods=4).rms)[:, 0, :]
    doubled = subharmonic_present(rms[0], rms[1])
    first = int(np.argmax(doubled))
    assert doubled[first] and doubled[first:].all() and not doubled[:first].any()
    assert amplitudes[first - 1] < threshold <= amplitudes[first]
    # the sliders damp the tongue: its threshold is above the same bead's without them (12 nm)
    assert threshold > period_doubling_threshold(lydon_fitted_bead(), 7900.0, amplitudes, steps_per_period=48)
