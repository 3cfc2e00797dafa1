"""Driven chains: static state, lock-in against closed forms, conservation, derivatives, and
an independent integrator (scipy's DOP853 on an ODE written here, not the package's)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import (
    linear_mode_frequencies_hz,
    linear_response,
    lydon_bead,
    lydon_fitted_bead,
    uneven_chain,
)
from scipy.integrate import solve_ivp

from hertzchain.driven import DrivenChain, kernel, lockin, lockin_grid, settle_periods
from hertzchain.driven import drive as drives


def test_from_materials_stiffness_and_static_equilibrium():
    chain = lydon_bead(n_beads=3)
    kappa = np.asarray(chain.contact_kappa_n_m1p5)
    # sphere-flat between equal steels is sqrt(2) x sphere-sphere; 9.7576e9 sphere-sphere (Lydon's scripts)
    assert kappa[1] == pytest.approx(9.7576e9, rel=1e-4)
    assert kappa[0] == pytest.approx(np.sqrt(2.0) * kappa[1], rel=1e-12)
    assert kappa[3] == pytest.approx(kappa[0], rel=1e-12)
    overlap = np.asarray(chain.static_overlap_m())
    np.testing.assert_allclose(kappa * overlap**1.5, 4.5, rtol=1e-13)
    # a rigid wall (Y = inf) doubles the compliance's share: 2 sqrt(2) x sphere-sphere; and the
    # mass from the density of a full sphere (316 steel, 7990 kg/m^3: 28.9 g, Lydon's README)
    rigid = DrivenChain.from_materials(
        n_beads=2, bead_radius_m=9.525e-3, bead_density_kg_m3=7990.0, bead_youngs_pa=193e9, bead_poisson=0.3,
        driver_youngs_pa=193e9, driver_poisson=0.3, wall_youngs_pa=np.inf, wall_poisson=0.3, precompression_n=3.0)
    assert float(rigid.contact_kappa_n_m1p5[2]) == pytest.approx(2 * np.sqrt(2) * kappa[1], rel=1e-12)
    assert float(rigid.bead_mass_kg[0]) == pytest.approx(0.0289, abs=5e-5)
    for c in (chain, uneven_chain()):
        p = kernel.kernel_params(c)
        state = kernel.static_state(p, jnp.zeros(3))
        force = kernel.contact_forces(p, state.displacement_m, state.velocity_m_s, jnp.zeros(3), jnp.zeros(3))
        np.testing.assert_allclose(np.asarray(force), float(c.precompression_n), rtol=1e-13)
        net = np.asarray(state.contact_accel_m_s2) * np.asarray(c.bead_mass_kg)[:, None]
        assert np.max(np.abs(net)) < 1e-13 * float(c.precompression_n)


@pytest.mark.parametrize("chain_name", ["one_bead", "uneven"])
def test_lockin_of_linear_response_matches_closed_form(chain_name):
    chain = lydon_bead(damping_rate_per_s=3000.0) if chain_name == "one_bead" else uneven_chain()
    exact_all = linear_response(chain, np.linspace(100.0, 20000.0, 4000))
    peak_f = np.linspace(100.0, 20000.0, 4000)[np.argmax(np.abs(exact_all[0]))]
    frequencies = peak_f * np.array([0.8, 0.97, 1.0, 1.05, 1.3])
    amplitude = 1e-12  # m: x / delta_0 ~ 1e-5, the Hertz nonlinearity enters at (x / delta_0)^2
    hold = settle_periods(chain, frequencies.max(), tolerance=1e-7)
    for bead in sorted({1, chain.n_beads}):
        grid = lockin_grid(chain, frequencies, [amplitude], bead=bead, harmonics=(1.0,), ramp_periods=10,
                           hold_periods=hold, window_periods=2, steps_per_period=1500)
        exact = linear_response(chain, frequencies)[bead - 1] * amplitude
        got = np.asarray(grid.complex_amplitude[0, :, 0])
        scale = np.max(np.abs(exact_all[bead - 1])) * amplitude
        # Verlet at 1500 steps a period shifts the resonance by ~(2 pi / 1500)^2 / 24 = 7e-7
        assert np.max(np.abs(got - exact)) < 1e-4 * scale, (bead, got, exact)
        np.testing.assert_allclose(np.asarray(grid.rms[0, :, 0]), np.abs(exact) / np.sqrt(2), rtol=2e-4)
    if chain_name == "one_bead":
        return
    # force sensors at the driver face and at the wall: k_0 (a - X_1) and k_n X_n
    k = np.asarray(chain.contact_stiffness_n_m())
    displacement = linear_response(chain, frequencies) * amplitude / (2j * np.pi * frequencies)
    for contact, exact in ((0, k[0] * (amplitude - displacement[0])), (chain.n_beads, k[-1] * displacement[-1])):
        grid = lockin_grid(chain, frequencies, [amplitude], quantity="force", contact=contact, harmonics=(1.0,),
                           ramp_periods=10, hold_periods=hold, window_periods=2, steps_per_period=1500)
        got = np.asarray(grid.complex_amplitude[0, :, 0])
        assert np.max(np.abs(got - exact)) < 1e-4 * np.max(np.abs(exact)), (contact, got, exact)


def test_lockin_function_reads_amplitude_phase_and_rejects_partial_periods():
    t = np.arange(400) * 1e-5  # 4 ms: 40 periods of 10 kHz, 2 of 500 Hz
    signal = 0.3 * np.cos(2 * np.pi * 10e3 * t + 0.7) + 0.05 * np.sin(2 * np.pi * 500 * t) + 0.2
    at_f = lockin(signal, 1e-5, 10e3)
    assert float(at_f.rms) == pytest.approx(0.3 / np.sqrt(2), rel=1e-12)
    assert float(at_f.phase_rad) == pytest.approx(0.7, abs=1e-12)
    at_half = lockin(signal, 1e-5, 500.0)
    assert float(at_half.rms) == pytest.approx(0.05 / np.sqrt(2), rel=1e-12)
    assert float(at_half.phase_rad) == pytest.approx(-np.pi / 2, abs=1e-12)
    with pytest.raises(ValueError, match="whole number"):
        lockin(signal, 1e-5, 333.0)


def _run_recorded(chain, frequency_hz, amplitude_m, periods, ramp_periods, steps_per_period):
    """Kernel run recording the bead state, the driver's motion and contact forces per step."""
    p = kernel.kernel_params(chain)
    f = jnp.asarray([frequency_hz])
    dt = 1.0 / (f * steps_per_period)
    drive = drives.harmonic_segment(f, dt, steps_per_period, 0.0, jnp.asarray([amplitude_m]),
                                    ramp_periods * steps_per_period)

    def record(s, u, u_dot):
        force = kernel.contact_forces(p, s.displacement_m, s.velocity_m_s, u, u_dot)
        return s.displacement_m[:, 0], s.velocity_m_s[:, 0], u[0], u_dot[0], force[:, 0]

    state = kernel.static_state(p, f)
    _, rec = kernel.advance(p, state, dt, drive, jnp.arange(1, periods * steps_per_period + 1), record=record)
    return float(dt[0]), [np.asarray(r) for r in rec]


def test_energy_balance_of_a_driven_conservative_chain():
    chain = eqx.tree_at(lambda c: c.damping_rate_per_s, uneven_chain(), jnp.zeros(3))
    dt, (x, v, u, u_dot, force) = _run_recorded(chain, 3000.0, 40e-9, periods=12, ramp_periods=4,
                                                steps_per_period=400)
    kappa = np.asarray(chain.contact_kappa_n_m1p5)
    overlap0 = np.asarray(chain.static_overlap_m())
    front = np.concatenate([u[:, None], x], axis=1)
    back = np.concatenate([x, np.zeros((len(u), 1))], axis=1)
    overlap = overlap0 + front - back
    energy = 0.5 * np.sum(np.asarray(chain.bead_mass_kg) * v**2, axis=1) + np.sum(
        0.4 * kappa * np.maximum(overlap, 0.0) ** 2.5, axis=1)
    energy0 = np.sum(0.4 * kappa * overlap0**2.5)
    power = force[:, 0] * u_dot  # the driver pushes contact 0 at speed u_dot
    work = np.concatenate([[0.0], np.cumsum(0.5 * dt * (power[1:] + power[:-1]))])
    work = work + 0.5 * dt * power[0]  # first step from rest (power 0 at t = 0)
    gained = energy - energy0
    assert np.max(np.abs(gained)) > 1e-9  # the drive does put energy in
    assert np.max(np.abs(gained - work)) < 2e-4 * np.max(np.abs(gained))
    assert np.all(overlap > 0)  # 40 nm of drive keeps every contact closed: no clipping here


def test_momentum_balance_with_damping():
    chain = uneven_chain()
    dt, (_, v, _, _, force) = _run_recorded(chain, 2500.0, 30e-9, periods=10, ramp_periods=3,
                                                steps_per_period=400)
    m = np.asarray(chain.bead_mass_kg)
    gamma = np.asarray(chain.damping_rate_per_s)
    momentum = v @ m
    net = force[:, 0] - force[:, -1] - (v * m * gamma).sum(axis=1)
    impulse = np.concatenate([[0.0], np.cumsum(0.5 * dt * (net[1:] + net[:-1]))]) + 0.5 * dt * net[0]
    assert np.max(np.abs(momentum)) > 1e-6
    assert np.max(np.abs(momentum - impulse)) < 1e-4 * np.max(np.abs(momentum))


def test_jacfwd_matches_finite_differences():
    chain = lydon_bead(precompression_n=0.2, damping_rate_per_s=1500.0)
    frequencies = np.array([3900.0, 4300.0, 4600.0])
    amplitudes = np.array([2e-9, 20e-9])
    options = {"harmonics": (1.0, 0.5), "ramp_periods": 6, "hold_periods": 10, "window_periods": 2,
               "steps_per_period": 32}

    def model(theta):
        f0, kappa_scale, gamma, drive_scale = theta
        c = eqx.tree_at(lambda c: (c.precompression_n, c.contact_kappa_n_m1p5, c.damping_rate_per_s), chain,
                        (f0, chain.contact_kappa_n_m1p5 * kappa_scale, chain.damping_rate_per_s * 0 + gamma))
        grid = lockin_grid(c, frequencies, amplitudes * drive_scale, **options)
        return jnp.concatenate([grid.rms[0].ravel(), grid.phase_rad[0].ravel()])

    theta = jnp.array([0.2, 1.0, 1500.0, 1.0])
    jac = np.asarray(jax.jacfwd(model)(theta))
    # the same numbers with the whole model under an outer jit (the chain's constants then traced too)
    np.testing.assert_allclose(np.asarray(jax.jit(model)(theta)), np.asarray(model(theta)), rtol=1e-12, atol=1e-15)
    for i in range(4):
        step = 1e-5 * float(theta[i])
        up = np.asarray(model(theta.at[i].add(step)))
        down = np.asarray(model(theta.at[i].add(-step)))
        fd = (up - down) / (2 * step)
        scale = np.abs(fd).max()
        assert scale > 0
        np.testing.assert_allclose(jac[:, i], fd, atol=1e-6 * scale, rtol=1e-5)


def independent_lockin(chain, frequency_hz, amplitude_m, ramp, hold, window, bead):
    """The same experiment integrated by scipy (DOP853, rtol 1e-11) on an ODE written here:
    Hertz contacts with Kuwabara-Kono damping (clipped at 0), drag -m gamma v, smooth ramp,
    lock-in on 256 samples a period."""
    m = np.asarray(chain.bead_mass_kg)
    kappa = np.asarray(chain.contact_kappa_n_m1p5)
    gamma = np.asarray(chain.damping_rate_per_s)
    eta = float(chain.eta_s)
    d0 = (float(chain.precompression_n) / kappa) ** (2 / 3)
    n = m.size
    w = 2 * np.pi * frequency_hz
    t_ramp = ramp / frequency_hz

    def driver(t):  # displacement and velocity
        s = min(max(t / t_ramp, 0.0), 1.0)
        envelope = amplitude_m * (10 * s**3 - 15 * s**4 + 6 * s**5)
        rate = amplitude_m * 30 * s**2 * (1 - s) ** 2 / t_ramp if s < 1 else 0.0
        return envelope * np.cos(w * t), rate * np.cos(w * t) - envelope * w * np.sin(w * t)

    def rhs(t, y):
        x, v = y[:n], y[n:]
        u, u_dot = driver(t)
        overlap = d0 + np.concatenate([[u], x]) - np.concatenate([x, [0.0]])
        rate = np.concatenate([[u_dot], v]) - np.concatenate([v, [0.0]])
        closed = np.maximum(overlap, 0.0)
        force = np.where(overlap > 0, np.maximum(kappa * closed**1.5 + 1.5 * eta * kappa * np.sqrt(closed) * rate, 0), 0)
        return np.concatenate([v, (force[:-1] - force[1:]) / m - gamma * v])

    t_end = (ramp + hold) / frequency_hz
    t_window = np.linspace(t_end - window / frequency_hz, t_end, window * 256, endpoint=False)
    sol = solve_ivp(rhs, (0.0, t_end), np.zeros(2 * n), method="DOP853", rtol=1e-11, atol=1e-18,
                    t_eval=t_window, max_step=1 / (40 * frequency_hz))
    velocity = sol.y[n + bead - 1]
    return lockin(velocity, t_window[1] - t_window[0], frequency_hz, start_time_s=t_window[0]).complex_amplitude


@pytest.mark.parametrize("n_beads, eta_s", [(1, 0.0), (2, 0.0), (2, 2e-6)])
def test_agrees_with_an_independent_integrator_in_the_nonlinear_regime(n_beads, eta_s):
    # F0 = 0.15 N: static overlaps of 49 nm (faces) and 78 nm (between beads), so a few nm of
    # drive near a resonance bends it (Lydon's regime); with and without contact damping
    chain = eqx.tree_at(lambda c: c.eta_s, lydon_bead(n_beads=n_beads, precompression_n=0.15,
                                                       damping_rate_per_s=1500.0), jnp.asarray(eta_s))
    frequencies = linear_mode_frequencies_hz(chain)[-1] * np.array([0.9, 0.98])
    amplitude = 4e-9
    ramp, hold, window = 8, 24, 2
    grid = lockin_grid(chain, frequencies, [amplitude], bead=n_beads, harmonics=(1.0,), ramp_periods=ramp,
                       hold_periods=hold, window_periods=window, steps_per_period=512)
    reference = np.array([independent_lockin(chain, f, amplitude, ramp, hold, window, n_beads) for f in frequencies])
    got = np.asarray(grid.complex_amplitude[0, :, 0])
    # Verlet's error at 512 steps a period (a resonance shift of 6e-6) and the hold's residual
    # transient (e^-3.5 of the ramp's, which the smooth ramp keeps small) bound this.
    np.testing.assert_allclose(got, reference, rtol=1e-3)
    # and the nonlinearity is really at work: the response is 3.6-7 % off the linearised chain's
    linear = linear_response(chain, frequencies)[n_beads - 1] * amplitude
    assert np.max(np.abs(linear - reference) / np.abs(reference)) > 0.02
    if eta_s > 0:  # and the contact damping is really at work
        undamped = lockin_grid(eqx.tree_at(lambda c: c.eta_s, chain, jnp.asarray(0.0)), frequencies, [amplitude],
                               bead=n_beads, harmonics=(1.0,), ramp_periods=ramp, hold_periods=hold,
                               window_periods=window, steps_per_period=512)
        assert np.min(np.abs(np.asarray(undamped.complex_amplitude[0, :, 0]) - got) / np.abs(got)) > 0.05


def test_bad_input_names_the_field():
    chain = lydon_bead()
    with pytest.raises(ValueError, match="bead"):
        lockin_grid(chain, [4000.0], [1e-9], bead=2)
    with pytest.raises(ValueError, match="harmonics"):
        lockin_grid(chain, [4000.0], [1e-9], harmonics=(0.5,), window_periods=3)
    with pytest.raises(ValueError, match="steps_per_period"):
        lockin_grid(chain, [50.0], [1e-9], steps_per_period=16)
    with pytest.raises(ValueError, match="contact_kappa_n_m1p5"):
        DrivenChain(bead_mass_kg=[0.1, 0.1], contact_kappa_n_m1p5=[1e9, 1e9], precompression_n=1.0,
                    damping_rate_per_s=0.0)
    with pytest.raises(ValueError, match="precompression_n"):
        DrivenChain(bead_mass_kg=[0.1], contact_kappa_n_m1p5=[1e9, 1e9], precompression_n=-1.0,
                    damping_rate_per_s=0.0)
    with pytest.raises(ValueError, match="drive_amplitudes_m"):
        lockin_grid(chain, [4000.0], [-1e-9])
    with pytest.raises(ValueError, match="contact"):
        lockin_grid(chain, [4000.0], [1e-9], quantity="force")
    with pytest.raises(ValueError, match="contact"):
        lockin_grid(chain, [4000.0], [1e-9], contact=1)


def test_smooth_step_is_smooth():
    s = jnp.linspace(-0.5, 1.5, 2001)
    value, slope = drives.smooth_step(s)
    assert float(value[0]) == 0.0 and float(value[-1]) == 1.0
    numeric = np.gradient(np.asarray(value), np.asarray(s))
    np.testing.assert_allclose(np.asarray(slope)[1:-1], numeric[1:-1], atol=2e-3)


def test_resonance_bending_of_the_fitted_bead_matches_the_independent_model():
    # research notes (real-data.md): the fitted model (drive scale 1.12 x the files' 6.834e-7 m/V)
    # bends the resonance by -6.5 % from the lowest to the highest drive, and its peak velocity
    # per nm of drive falls to 0.87 of the lowest drive's
    chain = lydon_fitted_bead()
    frequencies = np.arange(3000.0, 4700.1, 5.0)
    drives = 1.12 * np.array([0.683e-9, 6.66e-9])
    rms = np.asarray(lockin_grid(chain, frequencies, drives, harmonics=(1.0,)).rms[0])
    peak = frequencies[np.argmax(rms, axis=0)]
    assert peak[1] / peak[0] - 1 == pytest.approx(-0.065, abs=0.005)  # the notes quote two digits
    gain = rms.max(axis=0) / drives
    assert gain[1] / gain[0] == pytest.approx(0.87, abs=0.01)
