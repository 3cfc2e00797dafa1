"""The linearised chain (hertzchain.driven.linear) against closed forms, finite differences
and a time-domain integration of the full Hertz chain by scipy."""

import jax
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hertzchain.contact import hertz_force
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import (
    band_structure,
    frequency_response,
    monatomic_band_edge_hz,
    normal_modes,
)

MASS = 0.028  # kg, the 19.05 mm stainless beads of Lydon et al.
KAPPA = 9.7576e9  # N/m^1.5, their sphere-sphere Hertz constant


def _chain(masses, kappas, f0, gamma=0.0):
    return DrivenChain(np.asarray(masses, float), np.asarray(kappas, float), f0, gamma)


def test_contact_stiffness_is_the_slope_of_the_hertz_law():
    for f0 in (0.1, 1.0, 4.5):
        k = np.asarray(_chain([MASS], [KAPPA, 2 * KAPPA], f0).contact_stiffness_n_m())
        delta0 = (f0 / np.array([KAPPA, 2 * KAPPA])) ** (2 / 3)
        h = 1e-4 * delta0
        slope = (np.asarray(hertz_force(delta0 + h, np.array([KAPPA, 2 * KAPPA])))
                 - np.asarray(hertz_force(delta0 - h, np.array([KAPPA, 2 * KAPPA])))) / (2 * h)
        np.testing.assert_allclose(k, slope, rtol=1e-7)


def test_one_bead_between_two_flats():
    """The setup's constants give 5077 Hz (sphere-flat kappa = sqrt(2) x sphere-sphere, F0 = 4.5 N),
    and the response is the driven oscillator's k0 / (k0 + k1 - w^2 m + i w m gamma)."""
    kappa = np.full(2, KAPPA * np.sqrt(2))
    gamma = 900.0
    chain = _chain([MASS], kappa, 4.5, gamma)
    (f,), _ = normal_modes(chain)
    assert float(f) == pytest.approx(5077, abs=1)
    k = 1.5 * kappa ** (2 / 3) * 4.5 ** (1 / 3)
    freqs = np.linspace(3000, 7000, 9)
    w = 2 * np.pi * freqs
    x, force = frequency_response(chain, freqs)
    expected = k[0] / (k.sum() - w**2 * MASS + 1j * w * MASS * gamma)
    np.testing.assert_allclose(np.asarray(x[:, 0]), expected, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(force[:, 0]), k[0] * (1 - expected), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(force[:, 1]), k[1] * expected, rtol=1e-12)


def test_monatomic_chain_modes_and_band():
    """Fixed-fixed chain of n equal beads: f_j = (1/pi) sqrt(k/m) sin(j pi / (2(n+1))); the
    periodic chain's band 2 sqrt(k/m)|sin(q/2)| and its edge, which for these beads is the
    4.96 kHz F0^(1/6) of the authors' scripts."""
    n, f0 = 12, 5.0
    modes, shapes = normal_modes(_chain(np.full(n, MASS), np.full(n + 1, KAPPA), f0))
    k = 1.5 * KAPPA ** (2 / 3) * f0 ** (1 / 3)
    j = np.arange(1, n + 1)
    np.testing.assert_allclose(np.asarray(modes), np.sqrt(k / MASS) / np.pi * np.sin(j * np.pi / (2 * (n + 1))), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(shapes.T @ np.diag(np.full(n, MASS)) @ shapes), np.eye(n), atol=1e-10)
    q = np.linspace(-np.pi, np.pi, 21)
    bands = np.asarray(band_structure(np.array([MASS]), np.array([KAPPA]), f0, q))
    np.testing.assert_allclose(bands[:, 0], np.sqrt(k / MASS) / np.pi * np.abs(np.sin(q / 2)), rtol=1e-10, atol=1e-9)
    edge = float(monatomic_band_edge_hz(MASS, KAPPA, f0))
    assert edge == pytest.approx(4.96e3 * f0 ** (1 / 6), rel=0.005)


def test_diatomic_band_gap_closed_form():
    """Two masses per cell: at q = pi the bands sit at sqrt(2k/m2) and sqrt(2k/m1); at q = 0
    the optical band at sqrt(2k (1/m1 + 1/m2))."""
    m1, m2, f0 = MASS, 0.3 * MASS, 2.0
    k = 1.5 * KAPPA ** (2 / 3) * f0 ** (1 / 3)
    bands = np.asarray(band_structure(np.array([m1, m2]), np.array([KAPPA, KAPPA]), f0, np.array([0.0, np.pi])))
    two_pi = 2 * np.pi
    np.testing.assert_allclose(bands[0], [0.0, np.sqrt(2 * k * (1 / m1 + 1 / m2)) / two_pi], atol=1e-3)
    np.testing.assert_allclose(bands[1], [np.sqrt(2 * k / m1) / two_pi, np.sqrt(2 * k / m2) / two_pi], rtol=1e-10)


def test_response_equals_the_small_drive_limit_of_the_hertz_chain():
    """Three beads, Hertz contacts, viscous damping, integrated by scipy's DOP853 from the
    static equilibrium under a small harmonic face motion: the steady amplitude of every bead
    (projected on e^{i w t} over whole periods) equals the linear response to 1e-3 (the
    drive is 1e-3 of the static overlap, so the nonlinearity enters at that order)."""
    masses = np.array([MASS, 0.5 * MASS, MASS])
    kappas = np.array([KAPPA * np.sqrt(2), KAPPA, 0.8 * KAPPA, KAPPA * np.sqrt(2)])
    f0, gamma, freq = 2.0, 2000.0, 3100.0
    delta0 = (f0 / kappas) ** (2 / 3)
    drive = 1e-3 * delta0.min()
    w = 2 * np.pi * freq
    positions0 = -np.cumsum(delta0)[:-1]  # face at 0, the chain along -x: contact j's compression is x_{j-1} - x_j
    wall = positions0[-1] - delta0[-1]

    def rhs(t, y):
        x, v = y[:3], y[3:]
        ends = np.concatenate([[drive * np.sin(w * t)], x, [wall]])
        force = kappas * np.maximum(ends[:-1] - ends[1:], 0.0) ** 1.5
        return np.concatenate([v, (force[:-1] - force[1:]) / masses - gamma * v])

    periods = 60
    t_end = periods / freq
    samples = np.linspace(t_end - 10 / freq, t_end, 10 * 64 + 1)
    sol = solve_ivp(rhs, (0, t_end), np.concatenate([positions0, np.zeros(3)]), method="DOP853",
                    rtol=1e-11, atol=1e-16, t_eval=samples)
    x = sol.y[:3, :-1] - positions0[:, None]
    t = samples[:-1]
    measured = 2 * np.mean(x * np.exp(-1j * w * t), axis=1)  # x = Re(X e^{iwt}) -> X
    response, _ = frequency_response(_chain(masses, kappas, f0, gamma), np.array([freq]))
    expected = np.asarray(response[0]) * drive * -1j  # drive sin(wt) = Re(-i e^{iwt})
    np.testing.assert_allclose(measured, expected, rtol=1e-3, atol=1e-3 * np.max(np.abs(expected)))


def test_response_is_differentiable_in_the_precompression():
    masses, kappas = np.full(2, MASS), np.array([KAPPA * np.sqrt(2), KAPPA, KAPPA * np.sqrt(2)])

    def peak(f0):
        x, _ = frequency_response(DrivenChain(masses, kappas, f0, 500.0), np.array([2500.0]))
        return jax.numpy.abs(x[0, 1])

    h = 1e-4
    fd = (peak(1.0 + h) - peak(1.0 - h)) / (2 * h)
    assert float(jax.grad(peak)(1.0)) == pytest.approx(float(fd), rel=1e-6)
