"""Closed-form solitary-wave theory against the paper and independent reference numbers."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain
from hertzchain import contact, pulses, theory
from hertzchain.materials import material

R = 0.013
RHO = 7780.0
Y = 203e9
NU = 0.3
MASS = 4.0 / 3.0 * math.pi * RHO * R**3


def _kappa():
    return contact.kappa_sphere_sphere(R, Y, NU, R, Y, NU)


def test_velocity_constants_of_the_paper():
    c_t = theory.long_wave_velocity_constant(R, RHO, Y, NU)
    assert float(c_t) == pytest.approx(198.919, abs=0.01)  # paper: 198.9
    unit = theory.lattice_speed_unit(R, MASS, _kappa())
    assert float(unit) == pytest.approx(222.398, abs=0.002)
    # Eq. (3) in lattice units is exactly (2/sqrt 5) 2R kappa^(1/3) m^(-1/2).
    assert float(c_t) == pytest.approx(2 / math.sqrt(5) * float(unit), rel=1e-12)
    c_n = theory.discrete_velocity_constant(R, MASS, _kappa())
    assert float(c_n) == pytest.approx(201.385, abs=0.03)
    assert float(c_n / c_t) == pytest.approx(1.01240, abs=3e-4)


def test_setup_constants_match_the_functions(paper_setup):
    numbers = theory.setup_constants(paper_setup)
    assert float(numbers["kappa_n_m1p5"]) * 1e-9 == pytest.approx(11.990, abs=0.001)
    assert float(numbers["wave_amplitude_n"]) == pytest.approx(333.34, abs=0.05)
    # 2 tau = 2R sqrt(10)/v at 333.3 N with C_n: 155.0 us (reference: 155.05 us with v = 530.27).
    assert float(numbers["speed_m_s"]) == pytest.approx(530.3, abs=0.3)
    assert float(numbers["duration_s"]) * 1e6 == pytest.approx(155.05, abs=0.1)
    assert float(numbers["wall_force_ratio"]) == pytest.approx(2**0.8, rel=1e-12)  # steel wall


def test_speed_amplitude_and_duration_relations():
    c = 201.37
    force = jnp.array([5.0, 50.0, 500.0])
    speed = theory.solitary_speed_m_s(force, c)
    np.testing.assert_allclose(theory.solitary_peak_force_n(speed, c), force, rtol=1e-13)
    # 2 tau * v is the constant 2 R sqrt(10).
    np.testing.assert_allclose(
        theory.solitary_duration_s(R, speed) * speed, 2 * R * math.sqrt(10), rtol=1e-14
    )
    # d v / d F = v / (6 F).
    grad = jax.grad(lambda f: theory.solitary_speed_m_s(f, c))(50.0)
    assert float(grad) == pytest.approx(float(speed[1]) / 300.0, rel=1e-12)


def test_impact_velocity_amplitude_relation():
    kappa = _kappa()
    # Asymptotic A = F_m / V0^(6/5) = 1413.66 N (m/s)^(-6/5) for the paper's beads.
    assert float(theory.wave_amplitude_n(1.0, kappa, MASS)) == pytest.approx(1413.66, abs=0.05)
    velocities = jnp.array([0.009, 0.3, 0.42])
    forces = theory.wave_amplitude_n(velocities, kappa, MASS)
    np.testing.assert_allclose(
        theory.impact_velocity_m_s(forces, kappa, MASS), velocities, rtol=1e-13
    )


def test_cos6_profile_is_one_hump():
    t = jnp.linspace(-3.0, 3.0, 601)
    f = theory.solitary_profile_n(t, 10.0, 0.0, 1.0)
    assert float(f[300]) == 10.0
    assert np.all(np.asarray(f)[np.abs(np.asarray(t)) > math.pi / 2] == 0.0)
    assert float(jnp.sum(f) * 0.01) == pytest.approx(10.0 * math.pi * 5 / 16, rel=1e-6)  # int cos^6
    half = theory.solitary_fwhm_s(1.0) / 2
    assert float(theory.solitary_profile_n(half, 1.0, 0.0, 1.0)) == pytest.approx(0.5, rel=1e-12)
    assert float(theory.solitary_fwhm_s(1.0)) / 2 == pytest.approx(0.4715, abs=1e-4)


@pytest.mark.parametrize(
    "name, paper_form, kappa_form",
    [
        ("plexiglass", 0.4232, 0.4293),
        ("soft_5GPa", 0.5171, 0.5171),
        ("Mg", 1.1608, 1.1583),
        ("Cu", 1.5770, 1.5880),
        ("Si", 1.6555, 1.6388),
        ("Fe", 1.7545, 1.7523),
        ("W", 1.9566, 1.9533),
    ],
)
def test_wall_force_ratio_estimates(name, paper_form, kappa_form):
    wall = material(name)
    assert float(theory.wall_force_ratio_paper(Y, wall.youngs_pa)) == pytest.approx(
        paper_form, abs=5e-4
    )
    kappa_w = contact.kappa_sphere_flat(R, Y, NU, wall.youngs_pa, wall.poisson)
    assert float(theory.wall_force_ratio(kappa_w, _kappa())) == pytest.approx(kappa_form, abs=5e-4)


def test_wall_force_ratio_rigid_and_equal_poisson_forms_agree():
    rigid = contact.kappa_sphere_flat(R, Y, NU, jnp.inf, NU)
    assert float(theory.wall_force_ratio(rigid, _kappa())) == pytest.approx(2**1.2, rel=1e-12)
    assert float(theory.wall_force_ratio_paper(Y, jnp.inf)) == pytest.approx(2**1.2, rel=1e-12)
    wall_y = jnp.array([3e9, 45e9, 411e9])
    kappa_w = contact.kappa_sphere_flat(R, Y, NU, wall_y, NU)
    np.testing.assert_allclose(
        theory.wall_force_ratio(kappa_w, _kappa()),
        theory.wall_force_ratio_paper(Y, wall_y),
        rtol=1e-12,
    )


def test_paper_dissipation_conversions():
    # The paper's own numbers: C_s = 0.17 gives mu = 0.19; C_v = 0.019 gives 1.55 us
    # (with C = 201.5).
    assert float(theory.mu_from_c_s(0.17, MASS)) == pytest.approx(0.1936, abs=2e-4)
    assert float(theory.eta_from_c_v(0.019, 201.5, R)) * 1e6 == pytest.approx(1.551, abs=2e-3)
    # Each conversion inverts the other.
    c_v = theory.c_v_from_eta(2e-6, 201.5, R)
    assert float(theory.eta_from_c_v(c_v, 201.5, R)) == pytest.approx(2e-6, rel=1e-12)
    assert float(theory.mu_from_c_s(theory.c_s_from_mu(0.19, MASS), MASS)) == pytest.approx(
        0.19, rel=1e-12
    )


def test_restitution_law_limits_and_maximum():
    """No dissipation: eps = 1. With both losses, eps is largest where the viscous loss's
    growth C_v F^(1/6)/6 balances the friction loss C_s/F: at F* = (6 C_s/C_v)^(6/7)."""
    assert float(theory.restitution_law(100.0, 0.0, 0.0)) == 1.0
    c_v, c_s = 0.019, 0.17
    best = (6 * c_s / c_v) ** (6 / 7)
    slope = jax.grad(lambda f: theory.restitution_law(f, c_v, c_s))
    assert float(slope(best)) == pytest.approx(0.0, abs=1e-14)
    assert float(slope(0.5 * best)) > 0 > float(slope(2 * best))


def _strain_profile(x, psi_m):
    return psi_m * jnp.cos(x / (R * math.sqrt(10))) ** 4


def test_cos4_strain_solves_the_travelling_wave_equation():
    """psi = (5/4)^2 (v/c)^4 cos^4 solves
    v^2 psi = c^2 [psi^(3/2) + (2/5) R^2 psi^(1/4) (psi^(5/4))'']."""
    c, v = 1.0, 0.2
    psi_m = (5 / 4) ** 2 * (v / c) ** 4
    d2 = jax.grad(jax.grad(lambda x: _strain_profile(x, psi_m) ** 1.25))
    x = jnp.linspace(-0.6, 0.6, 13) * math.pi / 2 * R * math.sqrt(10)
    psi = _strain_profile(x, psi_m)
    rhs = c**2 * (psi**1.5 + 0.4 * R**2 * psi**0.25 * jax.vmap(d2)(x))
    np.testing.assert_allclose(v**2 * psi, rhs, rtol=1e-10, atol=1e-22)


def test_continuum_kinetic_fraction_is_five_ninths():
    """Integrate the continuum energies of the cos^4 wave: K/(K+U) = 5/9; Hertz-only: 10/19."""
    c, v = 1.0, 0.3
    psi_m = (5 / 4) ** 2 * (v / c) ** 4
    half = math.pi / 2 * R * math.sqrt(10)
    x = jnp.linspace(-half, half, 20001)
    psi = _strain_profile(x, psi_m)
    slope = jax.vmap(jax.grad(lambda y: _strain_profile(y, psi_m) ** 1.25))(x)
    kinetic = jnp.trapezoid(v**2 * psi**2 / (2 * c**2), x)
    hertz = jnp.trapezoid(0.4 * psi**2.5, x)
    dispersive = jnp.trapezoid(-4 / 25 * R**2 * slope**2, x)
    assert float(kinetic / (kinetic + hertz + dispersive)) == pytest.approx(
        theory.KINETIC_FRACTION, rel=1e-7
    )
    assert float(kinetic / (kinetic + hertz)) == pytest.approx(
        theory.HERTZ_ONLY_KINETIC_FRACTION, rel=1e-7
    )


def test_theory_accepts_traced_setups(paper_setup):
    grad = jax.grad(
        lambda y: theory.setup_constants(hertzchain.ChainSetup(bead_youngs_pa=y))[
            "long_wave_velocity_constant"
        ]
    )(Y)
    # C_t is proportional to theta^(-1/3), i.e. to Y^(1/3).
    assert float(grad) == pytest.approx(198.919 / (3 * Y), rel=1e-4)


@pytest.fixture(scope="module")
def free_wave():
    """The paper's chain at 0.3 m/s, every contact, position and velocity recorded."""
    return hertzchain.simulate(
        hertzchain.ChainSetup(), t_end_s=0.85e-3, sample_interval_s=1e-6, record_all=True
    )


def test_kinetic_share_of_the_travelling_wave(free_wave, paper_setup):
    """Time-averaged K/(K+U) around the wave is 5/9 (paper: about 56 %), oscillating by about
    +-1 point as the peak hops from contact to contact."""
    time = np.asarray(free_wave.time_s)
    forces = np.asarray(free_wave.contact_forces_n)
    energy = np.asarray(free_wave.contact_elastic_j)
    velocity = np.asarray(free_wave.velocities_m_s)
    mass = np.concatenate(
        [[float(paper_setup.striker_mass_kg)], np.asarray(paper_setup.bead_mass_kg)]
    )
    shares = []
    for i in np.nonzero((time > 0.35e-3) & (time < 0.7e-3))[0]:
        k = int(np.argmax(forces[i]))
        contacts = slice(k - 5, k + 6)  # contacts k-5 .. k+5
        bodies = slice(k - 4, k + 6)  # the beads between them
        kinetic = 0.5 * np.sum(mass[bodies] * velocity[i, bodies] ** 2)
        shares.append(kinetic / (kinetic + np.sum(energy[i, contacts])))
    shares = np.asarray(shares)
    assert np.mean(shares) == pytest.approx(theory.KINETIC_FRACTION, abs=0.003)
    assert np.mean(shares) == pytest.approx(0.56, abs=0.02)
    assert 0.535 < shares.min() < 0.55 and 0.56 < shares.max() < 0.575


def test_impact_amplitude_factor_by_simulation(free_wave, paper_setup):
    """F_m at contacts 8-15 of the 21-bead chain is 0.03 % above the asymptotic a = 0.63955."""
    contacts = tuple(range(8, 16))
    forces = np.asarray(free_wave.contact_forces_n)[:, list(contacts)].T
    wave = pulses.incident_wave(free_wave.time_s, forces, contacts, R)
    kappa = float(paper_setup.contact_kappa()[1])
    a = wave.peak_force_n / (kappa**0.4 * MASS**0.6 * 0.3**1.2)
    assert a == pytest.approx(theory.IMPACT_AMPLITUDE_FACTOR * 1.0003, rel=3e-4)
    assert wave.peak_force_n == pytest.approx(
        float(theory.wave_amplitude_n(0.3, kappa, MASS)), rel=1e-3
    )


def test_discrete_speed_factor_by_simulation(free_wave, paper_setup):
    """v / (2R kappa^(1/3) m^(-1/2) F_m^(1/6)) from the peak times and peaks at contacts 8-15
    of the 21-bead chain is 0.9054, 1e-4 below the asymptotic DISCRETE_SPEED_FACTOR."""
    contacts = tuple(range(8, 16))
    forces = np.asarray(free_wave.contact_forces_n)[:, list(contacts)].T
    wave = pulses.incident_wave(free_wave.time_s, forces, contacts, R)
    unit = float(theory.lattice_speed_unit(R, MASS, float(paper_setup.contact_kappa()[1])))
    factor = wave.speed_m_s / (unit * wave.peak_force_n ** (1 / 6))
    assert factor == pytest.approx(theory.DISCRETE_SPEED_FACTOR, rel=1.5e-4)
    assert factor < theory.DISCRETE_SPEED_FACTOR


def _half_maximum_width(time, force):
    """Width of the first pulse at half its sampled maximum, crossings linearly interpolated."""
    i = int(np.argmax(force))
    half = force[i] / 2
    a = np.nonzero(force[:i] < half)[0][-1]
    b = i + np.nonzero(force[i:] < half)[0][0]
    left = time[a] + (half - force[a]) / (force[a + 1] - force[a]) * (time[a + 1] - time[a])
    right = time[b - 1] + (half - force[b - 1]) / (force[b] - force[b - 1]) * (time[b] - time[b - 1])
    return right - left


def test_discrete_fwhm_factor_by_simulation(free_wave):
    """The contact force's half-maximum width in units of 2R sqrt(10)/v grows to 0.4465
    (DISCRETE_FWHM_FACTOR) along contacts 8-15, narrower than the cos^6 pulse's 0.4715."""
    contacts = tuple(range(8, 16))
    time = np.asarray(free_wave.time_s)
    forces = np.asarray(free_wave.contact_forces_n)[:, list(contacts)].T
    wave = pulses.incident_wave(time, forces, contacts, R)
    lattice_time = float(theory.solitary_duration_s(R, wave.speed_m_s))
    factors = np.array([_half_maximum_width(time, f) for f in forces]) / lattice_time
    assert np.all(np.diff(factors) > 0)
    assert factors[-1] == pytest.approx(theory.DISCRETE_FWHM_FACTOR, abs=1e-4)
    assert factors[-1] < theory.COS6_HALF_WIDTH - 0.02
