"""Closed-form theory of Hertzian solitary waves (Nesterenko) and the paper's estimates.

Everything here is a `jax.numpy` function of SI quantities: it accepts arrays (broadcasting),
works under `jit`/`vmap` and is differentiable in every argument.

**Velocity constants.** A solitary wave of peak force $F_m$ travels at $v = C F_m^{1/6}$.
$C$ has units m s$^{-1}$ N$^{-1/6}$ (the paper's "standard units"). Two values matter:

- $C_t = (6/(5\\pi\\rho))^{1/2}(\\theta R)^{-1/3}$, the long-wavelength (continuum) theory,
  Eq. (3) of Job et al. (198.9 for the paper's beads). In lattice units it is exactly
  $C_t = (2/\\sqrt5)\\,2R\\kappa^{1/3}m^{-1/2}$.
- $C_n = 0.905516\\,2R\\kappa^{1/3}m^{-1/2}$, the discrete chain's free solitary wave with
  $F_m$ its peak contact force (201.385 for the paper's beads; the value measured on the
  paper's 21-bead chain at contacts 8-15 is 201.37, the paper quotes 201.5 +- 0.1).

**Duration.** $F(t) = F_m\\cos^6((t - t_0)/\\tau)$ with $2\\tau = 2R\\sqrt{10}/v$; the discrete
pulse fitted by a cos^6 above 5 % of its peak is about 4 % shorter (ratio 0.962).

**Energy split.** For the travelling wave the time-averaged kinetic share is exactly
$K/(K+U) = 5/9 = 0.5556$ (paper: "about 56 %"). Derivation: the potential energy is
homogeneous of degree 5/2 in the strains. In the discrete chain, the virial
$\\frac{d}{dt}\\sum_n m u_n\\dot u_n = 2K - \\sum_k \\delta_k F_k = 2K - \\tfrac52 U$ averages to
zero over one period of a wave of permanent form (it moves by one bead and the beads
behind it are at rest), so $\\langle K\\rangle = \\tfrac54\\langle U\\rangle$. The continuum
theory gives the same number when the energy of its dispersive term is kept: Eq. (2) is
$\\psi_{tt} = c^2\\partial_{xx}\\,\\delta W/\\delta\\psi$ with
$W = \\tfrac25\\psi^{5/2} - \\tfrac{4}{25}R^2[(\\psi^{5/4})_x]^2$, and on the $\\cos^4$ hump
$\\int K : \\int W = 70 : 56$. Dropping the dispersive energy (Hertz potential only) gives
$\\int K : \\int U = \\int\\cos^8 : \\int\\cos^{10} = 10 : 9$, i.e. 10/19 = 0.526. The
instantaneous share of the discrete wave oscillates between 0.544 and 0.567 as the peak
hops from contact to contact; the simulation (tests/test_theory.py) measures 0.5556.

Reference: S. Job, F. Melo, A. Sokolow, S. Sen, PRL 94, 178002 (2005); V. F. Nesterenko,
Dynamics of Heterogeneous Materials (Springer, 2001).
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from . import contact

# v / (2 R kappa^(1/3) m^(-1/2) F_m^(1/6)) of the free discrete solitary wave (peak F_m),
# measured on a 120-bead chain (contacts 60-109) with an adaptive DOP853 solution;
# tests/test_theory.py::test_discrete_speed_factor_by_simulation re-measures it from the
# arrival times at contacts 8-15 of the paper's 21-bead chain (1e-4 below: still settling).
DISCRETE_SPEED_FACTOR = 0.905516
# The same factor for the long-wave theory, Eq. (3): exactly 2/sqrt(5).
LONG_WAVE_SPEED_FACTOR = 2.0 / math.sqrt(5.0)
# a in F_m = a kappa^(2/5) m^(3/5) V0^(6/5): asymptotic peak of the solitary wave launched
# by a striker identical to the beads (contacts 60-109 of a 120-bead chain). On the paper's
# 21-bead chain, contacts 8-15 give 0.063 % more (the wave is still settling).
IMPACT_AMPLITUDE_FACTOR = 0.63955
# Time-averaged kinetic share K/(K+U) of a travelling solitary wave (exact, see above).
KINETIC_FRACTION = 5.0 / 9.0
# The continuum estimate that keeps only the Hertz potential (no dispersive energy).
HERTZ_ONLY_KINETIC_FRACTION = 10.0 / 19.0
# cos^6(x) = 1/2 at x = acos(2^(-1/6)): the FWHM of the cos^6 pulse in units of tau.
COS6_HALF_WIDTH = math.acos(2.0 ** (-1.0 / 6.0))
# Full width at half maximum of the discrete solitary wave's contact force in units of
# 2R sqrt(10)/v (the cos^6 pulse: 2 acos(2^(-1/6))/2 = 0.4715), measured with the free wave
# of DISCRETE_SPEED_FACTOR; tests/test_theory.py::test_discrete_fwhm_factor_by_simulation
# re-measures it at contacts 8-15 of the paper's chain.
DISCRETE_FWHM_FACTOR = 0.4465
# 2 tau of a cos^6 fitted above 5 % of the peak (`pulses.fit_cos6`, threshold 0.05) to the
# discrete pulse, in units of 2R sqrt(10)/v: dissipationless paper's chain, contacts 8-15,
# 5 N and 500 N; tests/test_pulses.py::test_pulse_duration_against_eq3 re-measures it.
DISCRETE_DURATION_FACTOR = 0.9619
# The wall force over the incident peak, simulated, divided by Eq. (5) (`wall_force_ratio`)
# for a wall of the beads' steel: 1.943 / 1.741 (adaptive DOP853 reference of the paper's
# chain); tests/test_reproduce.py::test_force_ratio_follows_eq5_trend_and_eq5_lies_below re-measures it.
WALL_FORCE_CORRECTION = 1.116
# C_v fitted to the simulated restitution of a viscoelastic chain (eta = 2 us, paper's
# chain: 0.00816) over the paper's conversion `c_v_from_eta` (0.0245 with C = 201.5);
# tests/test_reproduce.py::test_dissipation_and_the_papers_conversions re-measures it.
VISCOUS_CONVERSION_CORRECTION = 0.00816 / 0.0245
# C_s fitted to the simulated restitution of a chain with friction (mu = 0.19, paper's
# chain: 0.1145 N) over the paper's conversion `c_s_from_mu` (0.1668 N); the same test
# re-measures it.
FRICTION_CONVERSION_CORRECTION = 0.687


def lattice_speed_unit(bead_radius_m, bead_mass_kg, kappa_n_m1p5):
    """Natural unit of the velocity constant, $2R\\kappa^{1/3}m^{-1/2}$, m s^-1 N^-1/6.

    $v = c\\,(2R\\kappa^{1/3}m^{-1/2})F_m^{1/6}$ with a dimensionless $c$: $2/\\sqrt5$ in the
    long-wave theory, `DISCRETE_SPEED_FACTOR` = 0.905516 for the discrete chain. 222.398 for
    the paper's beads.
    """
    return 2.0 * bead_radius_m * kappa_n_m1p5 ** (1.0 / 3.0) / jnp.sqrt(bead_mass_kg)


def long_wave_velocity_constant(bead_radius_m, bead_density_kg_m3, bead_youngs_pa, bead_poisson):
    """$C_t = (6/(5\\pi\\rho))^{1/2}(\\theta R)^{-1/3}$ of Eq. (3), m s^-1 N^-1/6.

    The speed of Nesterenko's long-wavelength solitary wave is $v = C_t F_m^{1/6}$;
    198.9 for the paper's beads (R = 13 mm, rho = 7780 kg/m^3, Y = 203 GPa, nu = 0.3).
    """
    theta = contact.theta(bead_youngs_pa, bead_poisson)
    return jnp.sqrt(6.0 / (5.0 * jnp.pi * bead_density_kg_m3)) * (theta * bead_radius_m) ** (
        -1.0 / 3.0
    )


def discrete_velocity_constant(bead_radius_m, bead_mass_kg, kappa_n_m1p5):
    """$C_n = 0.905516\\,2R\\kappa^{1/3}m^{-1/2}$, m s^-1 N^-1/6: the discrete chain's value.

    Definition: the free solitary wave of a long chain of identical beads, $F_m$ its peak
    contact force, $v$ its speed. 201.385 for the paper's beads, 1.24 % above $C_t$.
    """
    return DISCRETE_SPEED_FACTOR * lattice_speed_unit(bead_radius_m, bead_mass_kg, kappa_n_m1p5)


def solitary_speed_m_s(peak_force_n, velocity_constant):
    """Speed $v = C F_m^{1/6}$ of a solitary wave of peak force `peak_force_n`, m/s.

    `velocity_constant` is $C$ in m s^-1 N^-1/6 (`long_wave_velocity_constant` or
    `discrete_velocity_constant`).
    """
    return velocity_constant * peak_force_n ** (1.0 / 6.0)


def solitary_peak_force_n(speed_m_s, velocity_constant):
    """Peak force $F_m = (v/C)^6$ of a solitary wave travelling at `speed_m_s`, N."""
    return (speed_m_s / velocity_constant) ** 6


def solitary_duration_s(bead_radius_m, speed_m_s):
    """The duration $2\\tau = 2R\\sqrt{10}/v$ of Eq. (3), s (the cos^6 pulse's $2\\tau$)."""
    return 2.0 * bead_radius_m * math.sqrt(10.0) / speed_m_s


def solitary_profile_n(time_s, peak_force_n, center_s, tau_s):
    """The cos^6 pulse $F_m\\cos^6((t - t_0)/\\tau)$ of Eq. (3), N.

    One hump only: zero where $|t - t_0| > \\pi\\tau/2$ (the force is compressive). The
    argument is clamped, so the function and its derivatives are finite everywhere.
    """
    raw = (time_s - center_s) / tau_s
    phase = jnp.clip(raw, -0.5 * jnp.pi, 0.5 * jnp.pi)
    return jnp.where(jnp.abs(raw) < 0.5 * jnp.pi, peak_force_n * jnp.cos(phase) ** 6, 0.0)


def solitary_fwhm_s(tau_s):
    """Full width at half maximum of the cos^6 pulse, $2\\,\\mathrm{acos}(2^{-1/6})\\,\\tau$, s.

    Relative to the duration $2\\tau$: 0.4715 (the discrete pulse gives
    `DISCRETE_FWHM_FACTOR` = 0.4465 relative to $2R\\sqrt{10}/v$).
    """
    return 2.0 * COS6_HALF_WIDTH * tau_s


def discrete_fwhm_s(bead_radius_m, speed_m_s):
    """Full width at half maximum of the discrete chain's solitary-wave contact force, s:
    `DISCRETE_FWHM_FACTOR` $\\cdot 2R\\sqrt{10}/v$ for a wave of speed $v$ (m/s)."""
    return DISCRETE_FWHM_FACTOR * 2.0 * bead_radius_m * math.sqrt(10.0) / speed_m_s


def wave_amplitude_n(
    striker_velocity_m_s, kappa_n_m1p5, bead_mass_kg, factor=IMPACT_AMPLITUDE_FACTOR
):
    """Peak force of the solitary wave launched by an identical striker, N.

    $F_m = a\\,\\kappa^{2/5}m^{3/5}V_0^{6/5}$ with $a$ = `factor` (0.63955, asymptotic; about
    1414 N (m/s)^-6/5 x V0^6/5 for the paper's beads, 333.3 N at 0.3 m/s). Exact in its
    V0 dependence (the dissipationless chain's scaling symmetry); only for a striker of the
    beads' mass and material.
    """
    return factor * kappa_n_m1p5**0.4 * bead_mass_kg**0.6 * striker_velocity_m_s**1.2


def impact_velocity_m_s(peak_force_n, kappa_n_m1p5, bead_mass_kg, factor=IMPACT_AMPLITUDE_FACTOR):
    """Striker velocity that launches a solitary wave of peak force `peak_force_n`, m/s.

    The inverse of `wave_amplitude_n`.
    """
    return (peak_force_n / (factor * kappa_n_m1p5**0.4 * bead_mass_kg**0.6)) ** (5.0 / 6.0)


def wall_force_ratio_paper(bead_youngs_pa, wall_youngs_pa):
    """Eq. (5): $F_{end}^{max}/F_{bead}^{max} \\approx 2^{6/5}(1 + Y_b/Y_w)^{-2/5}$.

    The paper's rough energy argument ($U_{end}^{max} \\approx 2U_{bead}^{max}$) with equal
    Poisson ratios. 2.297 for a rigid wall, 1.741 for a wall of the beads' steel; the
    simulated ratios are 2.238 and 1.943 (the estimate is 10-15 % low for walls of 3-211 GPa;
    `hertzchain reproduce` measures it, tests/test_reproduce.py checks it).
    `wall_youngs_pa = inf` is a rigid wall.
    """
    return 2.0**1.2 * (1.0 + bead_youngs_pa / wall_youngs_pa) ** (-0.4)


def wall_force_ratio(wall_kappa_n_m1p5, kappa_n_m1p5):
    """Eq. (5) with each contact's own stiffness: $2^{3/5}(\\kappa_w/\\kappa)^{2/5}$.

    From $U_{end}^{max} = 2U_{bead}^{max}$ with $U = \\tfrac25 F^{5/3}\\kappa^{-2/3}$; equals the
    paper's form when wall and beads have the same Poisson ratio (then
    $\\kappa_w/\\kappa = 2\\sqrt2/(1 + Y_b/Y_w)$).
    """
    return 2.0**0.6 * (wall_kappa_n_m1p5 / kappa_n_m1p5) ** 0.4


def restitution_law(peak_force_n, c_v, c_s):
    """The paper's restitution law $\\epsilon \\approx 1 - C_v F^{1/6} - C_s/F$ (dimensionless).

    `c_v` in N^-1/6, `c_s` in N; $\\epsilon = (F_{n+1}/F_n)^{5/6}$ between consecutive contacts.
    """
    return 1.0 - c_v * peak_force_n ** (1.0 / 6.0) - c_s / peak_force_n


def eta_from_c_v(c_v, velocity_constant, bead_radius_m):
    """The paper's conversion $\\eta \\approx 2\\sqrt{10}RC_v/(5C)$, s.

    **Warning:** this does not hold for the viscoelastic model it describes: simulating
    $\\eta$ = 2 us gives $C_v$ = 0.00816, 3.0 times less than this conversion predicts
    (it divides the dissipated work by the most compressed contact's energy instead of the
    wave's). Fit $\\eta$ with the simulator instead; use this only to compare with the paper.
    """
    return 2.0 * math.sqrt(10.0) * bead_radius_m * c_v / (5.0 * velocity_constant)


def c_v_from_eta(eta_s, velocity_constant, bead_radius_m):
    """Inverse of `eta_from_c_v`: the paper's $C_v = 5C\\eta/(2\\sqrt{10}R)$, N^-1/6.

    Same warning as `eta_from_c_v`.
    """
    return 5.0 * velocity_constant * eta_s / (2.0 * math.sqrt(10.0) * bead_radius_m)


def mu_from_c_s(c_s, bead_mass_kg, gravity_m_s2=9.81):
    """The paper's conversion $\\mu \\approx 4C_s/(5mg)$ (dimensionless).

    **Warning:** holds only to about 30-45 %: simulating $\\mu$ = 0.19 gives $C_s$ = 0.1145 N,
    0.687 times the 0.167 N this conversion predicts.
    """
    return 4.0 * c_s / (5.0 * bead_mass_kg * gravity_m_s2)


def c_s_from_mu(mu, bead_mass_kg, gravity_m_s2=9.81):
    """Inverse of `mu_from_c_s`: the paper's $C_s = 5\\mu mg/4$, N (same warning)."""
    return 1.25 * mu * bead_mass_kg * gravity_m_s2


def setup_constants(setup) -> dict:
    """Theory numbers of a `ChainSetup` of identical beads (uses bead 1 and contact 1).

    Returns a dict with `kappa_n_m1p5` (bead-bead), `wall_kappa_n_m1p5`, `bead_mass_kg`,
    `long_wave_velocity_constant`, `discrete_velocity_constant`, `wave_amplitude_n` (for an
    identical striker at the setup's velocity), `speed_m_s` and `duration_s` (discrete
    constant at that amplitude), `wall_force_ratio` (kappa form) and
    `wall_force_ratio_paper`.
    """
    radius = setup.bead_radius_m[0]
    mass = setup.bead_mass_kg[0]
    kappa = setup.contact_kappa()[min(1, setup.n_beads - 1)]
    wall_kappa = setup.wall_kappa()
    c_t = long_wave_velocity_constant(
        radius, setup.bead_density_kg_m3[0], setup.bead_youngs_pa[0], setup.bead_poisson[0]
    )
    c_n = discrete_velocity_constant(radius, mass, kappa)
    amplitude = wave_amplitude_n(setup.striker_velocity_m_s, kappa, mass)
    speed = solitary_speed_m_s(amplitude, c_n)
    return {
        "kappa_n_m1p5": kappa,
        "wall_kappa_n_m1p5": wall_kappa,
        "bead_mass_kg": mass,
        "long_wave_velocity_constant": c_t,
        "discrete_velocity_constant": c_n,
        "wave_amplitude_n": amplitude,
        "speed_m_s": speed,
        "duration_s": solitary_duration_s(radius, speed),
        "wall_force_ratio": wall_force_ratio(wall_kappa, kappa),
        "wall_force_ratio_paper": wall_force_ratio_paper(
            setup.bead_youngs_pa[-1], setup.wall_youngs_pa
        ),
    }
