"""Micro-slip friction at the beads' supports (`laws.IwanSupport`): the backbone and Masing
loop energies against their closed forms (the A^3 law below full slip, Coulomb's 4 F_s A far
above), and the energy books of a driven bead on such supports."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain import laws
from hertzchain.driven import DrivenChain, HarmonicSchedule, record_schedule

K, PHI = 2e6, 50e-9  # N/m, m: a Coulomb force of 0.05 N


def discrete_loop_energy(amplitude, elements):
    """Sum over elastic-perfectly-plastic elements of 4 f_j (A - phi_j)_+, J."""
    phi = (np.arange(elements) + 0.5) / elements * PHI
    return np.sum(4 * (K / elements) * phi * np.maximum(amplitude - phi, 0.0))


@eqx.filter_jit
def cycle_work(law, displacement):
    """Work the bead does on its supports along the displacement path (T,), J, per segment."""
    def step(slider, x):
        slider = law.update_state(slider, x)
        return slider, law.force(x, slider)

    _, force = jax.lax.scan(step, law.initial_state(displacement[0]), displacement)
    return -0.5 * (force[1:] + force[:-1]) * jnp.diff(displacement), force


def loop_energy(law, amplitude, samples=4000):
    """Energy dissipated over the second of two cycles x = A sin(2 pi s), J."""
    x = amplitude * np.sin(2 * np.pi * np.arange(2 * samples + 1) / samples)
    work, _ = cycle_work(law, jnp.asarray(x))
    return float(jnp.sum(work[samples:]))


def test_masing_loop_energy_follows_the_closed_forms():
    law = laws.IwanSupport(K, PHI, elements=64)
    for amplitude in (10e-9, 30e-9, 50e-9):
        measured = loop_energy(law, amplitude)
        assert measured == pytest.approx(discrete_loop_energy(amplitude, 64), rel=1e-5)
        # the continuum's 2/3 K A^3 / phi_max (the midpoint elements differ by O(1/E^2))
        assert measured == pytest.approx(2 / 3 * K * amplitude**3 / PHI, rel=2e-3)
    # far above full slip: Coulomb's 4 F_s A, less the 4/3 K phi^2 of the slip-free start
    amplitude = 40 * PHI
    coulomb = 4 * float(law.coulomb_force_n) * amplitude
    assert loop_energy(law, amplitude) == pytest.approx(coulomb - 4 / 3 * K * PHI**2, rel=2e-3)
    assert loop_energy(law, amplitude) == pytest.approx(coulomb, rel=0.02)
    # the backbone: F = K (x - x^2 / 2 phi) up to full slip, then F_s
    x = jnp.linspace(0.0, 2 * PHI, 201)
    _, force = cycle_work(law, x)
    backbone = np.where(x < PHI, K * (x - x**2 / (2 * PHI)), K * PHI / 2)
    np.testing.assert_allclose(-np.asarray(force), backbone, atol=2e-3 * K * PHI / 2)


def test_driven_bead_energy_books_close():
    # one bead on micro-slip supports plus viscous drag, driven to steady state: over a
    # period the driver's work equals the drag's loss plus the supports' Masing loop energy
    # at the bead's measured amplitude (no other loss: no contact damping)
    gamma, n = 500.0, 128
    support = laws.IwanSupport(K, PHI, elements=32)
    chain = DrivenChain([0.028], [1.38e10, 1.38e10], 4.5, gamma, support_friction=support)
    schedule = HarmonicSchedule.levels(4000.0, 30e-9, steps_per_period=n, ramp_periods=5, periods_per_level=60)
    traces = record_schedule(chain, schedule, beads=(1,), contacts=(0,), every_steps=1)
    u, x = np.asarray(traces.drive_m[0]), np.asarray(traces.displacement_m[0, 0])
    v, force = np.asarray(traces.velocity_m_s[0, 0]), np.asarray(traces.contact_force_n[0, 0])
    dt = 1.0 / (4000.0 * n)
    last = slice(-n - 1, None)  # the last period, both ends
    driver_work = np.sum(0.5 * (force[last][1:] + force[last][:-1]) * np.diff(u[last]))
    drag = np.sum(0.028 * gamma * 0.5 * (v[last][1:] ** 2 + v[last][:-1] ** 2) * dt)
    amplitude = 0.5 * (x[last].max() - x[last].min())
    assert 0.2 * PHI < amplitude < PHI  # micro-slip, not full slip
    supports = discrete_loop_energy(amplitude, 32)
    assert supports > 0.2 * drag  # the supports' loss matters in the books
    assert driver_work == pytest.approx(drag + supports, rel=3e-3)  # measured 3e-4 (the transient left)
    assert not chain.runs_on_fused_kernel
    with pytest.raises(ValueError, match="one per bead"):
        DrivenChain([0.028], [1.38e10, 1.38e10], 4.5, gamma, support_friction=laws.IwanSupport([K, K], PHI))


@pytest.mark.parametrize("power", [0.4, 0.7])
def test_segalman_spread_follows_its_closed_forms(power):
    # the elements spread so that a fraction (phi / phi_max)^p has slipped by a stretch phi:
    # the loop energy 4 K p A^(2+p) / (phi^p (1+p)(2+p)) below full slip, the backbone
    # K x (1 - (x/phi)^p / (1+p)) and the Coulomb force K phi p / (1+p) (the continuum's
    # closed forms; 256 midpoint elements)
    law = laws.IwanSupport(K, PHI, elements=256, slip_power=power)
    for amplitude in (10e-9, 30e-9):
        expected = 4 * K * power * amplitude ** (2 + power) / (PHI**power * (1 + power) * (2 + power))
        assert loop_energy(law, amplitude) == pytest.approx(expected, rel=5e-3)
    # the A^(2+p) law, not Mindlin's A^3: a factor 3^(2+p) from 10 to 30 nm
    assert loop_energy(law, 30e-9) / loop_energy(law, 10e-9) == pytest.approx(3 ** (2 + power), rel=5e-3)
    x = jnp.linspace(0.0, 2 * PHI, 201)
    _, force = cycle_work(law, x)
    coulomb = K * PHI * power / (1 + power)
    backbone = np.where(x < PHI, K * x * (1 - (x / PHI) ** power / (1 + power)), coulomb)
    np.testing.assert_allclose(-np.asarray(force), backbone, atol=5e-3 * coulomb)
    assert float(law.coulomb_force_n) == pytest.approx(coulomb, rel=5e-3)
    # a small harmonic motion: the energy per cycle over pi A^2, per unit of in-phase
    # stiffness lost, is 4 p / (pi (2 + p)) (the continuum's; 0.42 for the uniform spread)
    samples, amplitude = 4000, 5e-9
    phase = 2 * np.pi * np.arange(2 * samples + 1) / samples
    work, force = cycle_work(law, jnp.asarray(amplitude * np.sin(phase)))
    in_phase = -2 * np.mean(np.asarray(force)[samples:-1] * np.sin(phase[samples:-1])) / amplitude
    lost = float(jnp.sum(work[samples:])) / (np.pi * amplitude**2) / (K - in_phase)
    assert lost == pytest.approx(4 * power / (np.pi * (2 + power)), rel=2e-2)


def test_uniform_spread_is_the_default_and_the_power_is_checked():
    # p = 1 (the default) puts the elements at the uniform midpoints (j - 1/2) phi_max / E
    law = laws.IwanSupport(K, PHI, elements=16)
    np.testing.assert_array_equal(np.asarray(law._slip_at(0.0)), (np.arange(16) + 0.5) / 16 * PHI)
    with pytest.raises(ValueError, match="IwanSupport: slip_power"):
        laws.IwanSupport(K, PHI, slip_power=0.0)
