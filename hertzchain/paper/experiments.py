"""The simulations behind the paper's figures, and what is measured on them.

`run_sweep` simulates every run without an embedded sensor in one vmapped batch (one
compiled program): impact velocities x eta x mu on the paper's chain (Fig. 1, 2) and the
walls of Fig. 3; `run_sensor` the chain with the sensor of Eq. 4. The `measure_fig*`
functions return plain records (NumPy arrays and floats) holding the traces each figure
shows and the measured numbers. Definitions (they move the numbers by more than the
paper's error bars):

- Incident wave: parabolic peaks of the first pulse at contacts 8-15 of the 21-bead chain
  (`pulses.incident_wave`); speed = least-squares slope of $2RK$ against peak time,
  amplitude $F_m$ = mean peak force. $C$ = least-squares $v = CF_m^{1/6}$ over the impact
  velocities (`pulses.fit_velocity_law`).
- Duration $2\\tau$: cos^6 fit of the first pulse at contact 10, samples >= 5 % of its peak.
- Restitution: $\\epsilon_k = (F_{k+1}/F_k)^{5/6}$ from the peaks at contacts 6-17, divided by
  the same ratio of the dissipationless run at the same impact velocity.
- Wall force ratio: largest (parabolic) wall force over $F_m$ of contacts 8-15.
- Kinetic share: $K/(K+U)$ summed over the beads and contacts within 5 contacts of the most
  compressed one, averaged over the samples where that contact is 6..14.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import peaks, pulses, theory
from ..chain import ChainSetup
from ..materials import BEAD_STEEL, MATERIALS, PAPER_WALL_MATERIALS
from ..sensor import deconvolve_sensor
from .batch import run_setups
from .constants import PAPER_C_S, PAPER_C_V, PAPER_ETA_S, PAPER_MU, PAPER_SOFT_WALL_PA

SPEED_CONTACTS = tuple(range(8, 16))
RESTITUTION_CONTACTS = tuple(range(6, 18))
DURATION_CONTACT = 10
FAR_CONTACT = 10
SENSOR_BEAD = 10
KINETIC_WINDOW = 5
KINETIC_PEAK_RANGE = (6, 14)


@dataclasses.dataclass(frozen=True)
class Plan:
    """What the reproduction simulates.

    **Fields:** `velocities_m_s` impact velocities of the Fig. 2 sweep (must contain 0.3,
    the paper's Fig. 1 run); `wall_sweep_pa` wall moduli of the continuous Fig. 3a curve
    (Poisson ratio 0.3); `eta_s`, `mu` the dissipation of the damped runs;
    `sample_interval_s`; `chain_t_end_s` duration of the Fig. 1 and Fig. 2 runs;
    `wall_t_end_s` duration of the Fig. 3 runs (long enough for the secondary waves).
    """

    velocities_m_s: tuple[float, ...]
    wall_sweep_pa: tuple[float, ...]
    eta_s: float = PAPER_ETA_S
    mu: float = PAPER_MU
    sample_interval_s: float = 1e-6
    chain_t_end_s: float = 2.5e-3
    wall_t_end_s: float = 4e-3

    def __post_init__(self):
        if 0.3 not in self.velocities_m_s:
            raise ValueError("Plan.velocities_m_s must contain 0.3 m/s (the paper's Fig. 1 run).")
        if len(self.velocities_m_s) < 2:
            raise ValueError("Plan.velocities_m_s needs at least two impact velocities.")


FULL_PLAN = Plan(
    velocities_m_s=(0.01, 0.02, 0.05, 0.1, 0.2, 0.3),
    wall_sweep_pa=tuple(float(y) for y in np.geomspace(1e9, 3e12, 16)),
)
QUICK_PLAN = Plan(velocities_m_s=(0.02, 0.1, 0.3), wall_sweep_pa=())


def _np(x) -> np.ndarray:
    return np.asarray(x, dtype=float)


# `peaks.first_peak` compiled once per shape: every trace of a batch in one call.
_first_peaks = jax.jit(peaks.first_peak)


def _incident(time_s, forces_n, radius_m):
    """The incident wave over `SPEED_CONTACTS` for a batch, as `pulses.incident_wave` defines
    it (first-pulse parabolic peaks; speed = least-squares slope of 2RK against peak time,
    amplitude = mean peak force), with the peaks of the whole batch found in one call.

    `forces_n`: (..., len(SPEED_CONTACTS), n). Returns (speed m/s, amplitude N), shape (...).
    """
    times, peaks = (_np(a) for a in _first_peaks(time_s, forces_n))
    if np.any(times >= time_s[-2]):
        raise ValueError("The first pulse peaks at the end of a trace: record longer (t_end_s).")
    positions = 2.0 * radius_m * np.asarray(SPEED_CONTACTS, dtype=float)
    speed = np.zeros(times.shape[:-1])
    for index in np.ndindex(speed.shape):
        speed[index] = pulses.wave_speed(positions, times[index]).speed_m_s
    return speed, np.mean(peaks, axis=-1)


def _fit_first_pulses(time_s, forces_n, centers_s, half_widths_s):
    """`pulses.fit_cos6` of one pulse per trace, all traces in one call: samples outside
    `centers_s` +- `half_widths_s` are set to zero, which selects the pulse as the fit's
    `window_s` would. `forces_n` (M, n); returns the `Cos6Fit` of shape (M,)."""
    outside = np.abs(time_s[None, :] - centers_s[:, None]) > half_widths_s[:, None]
    return pulses.fit_cos6(time_s, np.where(outside, 0.0, forces_n))


# ---------------------------------------------------------------------------------------
# The chain sweep behind Fig. 1 and Fig. 2


@dataclasses.dataclass
class WallRuns:
    """The wall runs of the batch (0.3 m/s, no dissipation), one per wall: the named walls
    (`names`) then the modulus sweep (Poisson ratio 0.3). Arrays have a leading axis over
    them; `contact_n` maps a contact number to its force traces."""

    names: tuple[str, ...]
    youngs_pa: np.ndarray
    poisson: np.ndarray
    contact_n: dict[int, np.ndarray]
    wall_n: np.ndarray
    wall_elastic_j: np.ndarray
    kinetic_j: np.ndarray
    potential_j: np.ndarray
    initial_energy_j: np.ndarray


@dataclasses.dataclass
class Sweep:
    """Every dissipationless and dissipative run of the paper's chain behind Fig. 1-3.

    The chain sweep (steel wall) is impact velocities x eta [0, eta] x mu [0, mu]: its
    force and energy arrays have leading axes (n_velocities, 2, 2) and `contact_n` maps a
    contact number to its force traces. `full` holds every contact force, contact energy
    and body velocity of the (0.3 m/s, eta = 0, mu = 0) run. `walls` are the Fig. 3 runs.
    """

    plan: Plan
    setup: ChainSetup
    time_s: np.ndarray
    contact_n: dict[int, np.ndarray]
    wall_n: np.ndarray
    wall_elastic_j: np.ndarray
    kinetic_j: np.ndarray
    potential_j: np.ndarray
    dissipated_j: np.ndarray
    initial_energy_j: np.ndarray
    full: dict[str, np.ndarray]
    walls: WallRuns

    @property
    def fig1_index(self) -> int:
        """Index of 0.3 m/s in the velocity axis."""
        return self.plan.velocities_m_s.index(0.3)


SWEEP_CONTACTS = tuple(
    sorted(set(SPEED_CONTACTS) | set(RESTITUTION_CONTACTS) | {DURATION_CONTACT, FAR_CONTACT, 15})
)


def run_sweep(plan: Plan) -> Sweep:
    """Simulate the chain sweep of Fig. 1 / 2 and the walls of Fig. 3 in one vmapped batch
    (one compiled program; the time step resolves the stiffest wall)."""
    setup = ChainSetup()
    combos = [
        (v, eta, mu, float(setup.wall_youngs_pa), float(setup.wall_poisson))
        for v in plan.velocities_m_s for eta in (0.0, plan.eta_s) for mu in (0.0, plan.mu)
    ]
    named = wall_materials()
    walls = list(named.values()) + [(y, 0.3) for y in plan.wall_sweep_pa]
    combos += [(0.3, 0.0, 0.0, y, nu) for y, nu in walls]

    def fields(s):
        return s.striker_velocity_m_s, s.eta_s, s.mu, s.wall_youngs_pa, s.wall_poisson

    setups = [
        eqx.tree_at(fields, setup, tuple(jnp.asarray(x, dtype=float) for x in combo))
        for combo in combos
    ]
    traces = run_setups(
        setups, t_end_s=max(plan.chain_t_end_s, plan.wall_t_end_s),
        sample_interval_s=plan.sample_interval_s, contacts=SWEEP_CONTACTS, record_all=True,
    )
    shape = (len(plan.velocities_m_s), 2, 2)
    n_chain = int(np.prod(shape))

    def grid(x):
        array = _np(x)[:n_chain]
        return array.reshape(shape + array.shape[1:])

    def wall_part(x):
        return _np(x)[n_chain:]

    def recorded(part, *energies):
        """The contact and wall forces and the named energies of `traces`, each through `part`."""
        return {
            "contact_n": {k: part(traces.forces_n[f"contact_{k}"]) for k in SWEEP_CONTACTS},
            "wall_n": part(traces.forces_n["wall"]),
            **{name: part(getattr(traces, name)) for name in energies},
        }

    chosen = combos.index((0.3, 0.0, 0.0, float(setup.wall_youngs_pa), float(setup.wall_poisson)))
    return Sweep(
        plan=plan,
        setup=setup,
        time_s=_np(traces.time_s)[0],
        **recorded(grid, "wall_elastic_j", "kinetic_j", "potential_j", "dissipated_j", "initial_energy_j"),
        full={
            "contact_forces_n": _np(traces.contact_forces_n[chosen]),
            "contact_elastic_j": _np(traces.contact_elastic_j[chosen]),
            "velocities_m_s": _np(traces.velocities_m_s[chosen]),
        },
        walls=WallRuns(
            names=tuple(named),
            youngs_pa=np.asarray([y for y, _ in walls], dtype=float),
            poisson=np.asarray([nu for _, nu in walls], dtype=float),
            **recorded(wall_part, "wall_elastic_j", "kinetic_j", "potential_j", "initial_energy_j"),
        ),
    )


# ---------------------------------------------------------------------------------------
# Fig. 1: the paper's chain at 0.3 m/s


@dataclasses.dataclass
class Fig1:
    """Fig. 1 (b, c) and the travelling wave's energy split.

    Traces are for eta = [0, plan.eta_s] (first axis) at 0.3 m/s, mu = 0. `contact_n` is
    the force at `FAR_CONTACT`, `wall_n` the wall force; energies in J.
    """

    time_s: np.ndarray
    eta_s: np.ndarray
    contact_n: np.ndarray
    wall_n: np.ndarray
    kinetic_j: np.ndarray
    potential_j: np.ndarray
    dissipated_j: np.ndarray
    initial_energy_j: float
    kinetic_fraction: float
    kinetic_fraction_range: tuple[float, float]
    bead_energy_over_wave: float
    wave_energy_j: float
    wall_peak_time_s: np.ndarray  # (2,) time of the largest wall force, eta = [0, eta]
    ejection_time_s: np.ndarray  # (2,) first time after it with K >= 99 % of K + U


def _kinetic_share(sweep: Sweep):
    """Time-averaged K/(K+U) of the travelling wave (definition in the module docstring)."""
    setup = sweep.setup
    contact_force = sweep.full["contact_forces_n"]  # (n_samples, N)
    contact_energy = sweep.full["contact_elastic_j"]
    velocity = sweep.full["velocities_m_s"]  # (n_samples, N + 1): striker, beads
    masses = np.concatenate([[float(setup.striker_mass_kg)], _np(setup.bead_mass_kg)])
    kinetic_body = 0.5 * masses * velocity**2
    peak = np.argmax(contact_force, axis=1)
    strongest = np.max(contact_force, axis=1)
    # The incident wave only: before it reaches the wall, while a contact carries it.
    before_wall = np.arange(len(peak)) < np.argmax(sweep.wall_n[sweep.fig1_index, 0, 0])
    carried = strongest >= 0.5 * np.max(strongest[before_wall])
    lo, hi = KINETIC_PEAK_RANGE
    shares, energies = [], []
    for i in np.nonzero((peak >= lo) & (peak <= hi) & before_wall & carried)[0]:
        k = peak[i]
        first, last = k - KINETIC_WINDOW, k + KINETIC_WINDOW
        kinetic = float(np.sum(kinetic_body[i, first : last + 2]))  # beads first..last+1
        potential = float(np.sum(contact_energy[i, first : last + 1]))
        shares.append(kinetic / (kinetic + potential))
        energies.append(kinetic + potential)
    if not shares:
        raise ValueError("The wave never travelled between contacts 6 and 14: record longer.")
    return np.asarray(shares), float(np.mean(energies))


def measure_fig1(sweep: Sweep) -> Fig1:
    """Fig. 1 (b, c) from the sweep's 0.3 m/s runs without friction."""
    i = sweep.fig1_index
    shown = sweep.time_s <= sweep.plan.chain_t_end_s * (1 + 1e-9)
    time = sweep.time_s[shown]
    shares, wave_energy = _kinetic_share(sweep)
    radius = float(sweep.setup.bead_radius_m[0])
    _, amplitude = _incident(sweep.time_s, _stack_sweep(sweep, SPEED_CONTACTS)[i, 0, 0], radius)
    kappa = float(sweep.setup.contact_kappa()[1])
    bead_energy = 0.4 * float(amplitude) ** (5.0 / 3.0) / kappa ** (2.0 / 3.0)
    wall = sweep.wall_n[i, :, 0][:, shown]
    kinetic = sweep.kinetic_j[i, :, 0][:, shown]
    potential = sweep.potential_j[i, :, 0][:, shown]
    # Ejection: after the wall, the chain's remaining energy is again (almost) all kinetic.
    peak_index = np.argmax(wall, axis=-1)
    ejection = []
    for j in range(2):
        mostly_kinetic = kinetic[j] >= 0.99 * (kinetic[j] + potential[j])
        after = np.nonzero((np.arange(len(time)) > peak_index[j]) & mostly_kinetic)[0]
        ejection.append(float(time[after[0]]) if len(after) else math.nan)
    return Fig1(
        time_s=time,
        eta_s=np.array([0.0, sweep.plan.eta_s]),
        contact_n=sweep.contact_n[FAR_CONTACT][i, :, 0][:, shown],
        wall_n=wall,
        kinetic_j=kinetic,
        potential_j=potential,
        dissipated_j=sweep.dissipated_j[i, :, 0][:, shown],
        initial_energy_j=float(sweep.initial_energy_j[i, 0, 0]),
        kinetic_fraction=float(np.mean(shares)),
        kinetic_fraction_range=(float(np.min(shares)), float(np.max(shares))),
        bead_energy_over_wave=bead_energy / wave_energy,
        wave_energy_j=wave_energy,
        wall_peak_time_s=time[peak_index],
        ejection_time_s=np.asarray(ejection),
    )


def _stack_sweep(sweep: Sweep, contacts) -> np.ndarray:
    """Forces of `contacts` as (n_velocities, 2, 2, len(contacts), n_samples)."""
    return np.stack([sweep.contact_n[k] for k in contacts], axis=-2)


# ---------------------------------------------------------------------------------------
# Fig. 1a: the embedded sensor


@dataclasses.dataclass
class SensorRun:
    """The embedded sensor in bead `SENSOR_BEAD` at 0.3 m/s, eta = [0, plan.eta_s].

    `sensor_n` is the sensor spring's compression force, `back_n`/`front_n` the contact
    forces on its back (contact K-1) and front (contact K) halves, `wall_n` the wall force.
    """

    time_s: np.ndarray
    eta_s: np.ndarray
    sensor_n: np.ndarray
    back_n: np.ndarray
    front_n: np.ndarray
    wall_n: np.ndarray
    peak_ratio: float  # first-pulse peak of the sensor over the front contact's (eta = 0)
    peak_ratio_damped: float
    deconvolved_n: np.ndarray  # F_+ recovered from the sensor signal (Eq. 4, FFT)
    delay_s: np.ndarray  # t0 = 2R/v from the time of flight between the bead's contacts
    deconvolution_error: np.ndarray  # max |recovered - true| / true peak, incident pulse
    deconvolution_error_reflected: np.ndarray  # the same for the reflected pulse


def _deconvolve_pulses(time, sensor_n, front_n, delay_s, beta, f0_hz):
    """Recover F_+ pulse by pulse: the incident wave hits the back half first (delay +t0),
    the reflected one the front half (delay -t0). Returns (force, error incident, error
    reflected), errors as max |recovered - true| over the pulse (true force above 5 % of its
    peak) relative to the true peak."""
    found = peaks.find_pulses(time, sensor_n, noise_std_n=0.0)
    index = np.arange(len(time))
    recovered = np.zeros_like(sensor_n)
    errors = []
    for pulse, sign in zip(found[:2], (1.0, -1.0)):
        inside = (index >= pulse.start) & (index <= pulse.stop)
        part = _np(deconvolve_sensor(
            time, np.where(inside, sensor_n, 0.0), beta=beta, f0_hz=f0_hz,
            delay_s=sign * delay_s, noise_std_n=0.0,
        ))
        recovered = np.where(inside, part, recovered)
        true_peak = np.max(np.where(inside, front_n, 0.0))
        loaded = inside & (front_n >= 0.05 * true_peak)
        errors.append(float(np.max(np.abs(part - front_n)[loaded]) / true_peak))
    errors += [math.nan] * (2 - len(errors))
    return recovered, errors[0], errors[1]


def run_sensor(plan: Plan) -> SensorRun:
    """The paper's chain with the sensor of Eq. 4 (beta = 0.11, f0 = 85 kHz) in bead 10."""
    setup = ChainSetup(striker_velocity_m_s=0.3, sensor_beads=(SENSOR_BEAD,))
    setups = [eqx.tree_at(lambda s: s.eta_s, setup, jnp.asarray(eta, dtype=float))
              for eta in (0.0, plan.eta_s)]
    traces = run_setups(
        setups, t_end_s=plan.chain_t_end_s, sample_interval_s=plan.sample_interval_s,
        contacts=(SENSOR_BEAD - 1, SENSOR_BEAD),
    )
    time = _np(traces.time_s)[0]
    sensor = _np(traces.forces_n[f"sensor_{SENSOR_BEAD}"])
    front = _np(traces.forces_n[f"contact_{SENSOR_BEAD}"])
    back = _np(traces.forces_n[f"contact_{SENSOR_BEAD - 1}"])
    peak_time, peak = (_np(a) for a in _first_peaks(time, np.stack([sensor, front, back], axis=1)))
    ratio = peak[:, 0] / peak[:, 1]
    delay = peak_time[:, 1] - peak_time[:, 2]  # time of flight from the back to the front contact
    recovered = [
        _deconvolve_pulses(time, sensor[i], front[i], float(delay[i]), float(setup.sensor_beta),
                           float(setup.sensor_f0_hz))
        for i in range(2)
    ]
    return SensorRun(
        time_s=time,
        eta_s=np.array([0.0, plan.eta_s]),
        sensor_n=sensor,
        back_n=back,
        front_n=front,
        wall_n=_np(traces.forces_n["wall"]),
        peak_ratio=float(ratio[0]),
        peak_ratio_damped=float(ratio[1]),
        deconvolved_n=np.stack([r[0] for r in recovered]),
        delay_s=delay,
        deconvolution_error=np.array([r[1] for r in recovered]),
        deconvolution_error_reflected=np.array([r[2] for r in recovered]),
    )


# ---------------------------------------------------------------------------------------
# Fig. 2: speed, duration and restitution against amplitude


@dataclasses.dataclass
class Fig2:
    """Fig. 2 sweep: impact velocities x eta [0, eta] x mu [0, mu].

    Arrays have leading axes (n_velocities, 2, 2) for (velocity, eta index, mu index).
    `speed_m_s`, `amplitude_n`: incident wave over contacts 8-15; `duration_s`: 2 tau at
    contact 10 (NaN where its cos^6 fit did not converge: `duration_converged`) and
    `duration_amplitude_n` the parabolic peak there; `peak_forces_n`
    (..., n_restitution_contacts) the peaks at contacts 6-17; `restitution` the normalised
    epsilon (..., n - 1).
    """

    velocities_m_s: np.ndarray
    eta_s: np.ndarray
    mu: np.ndarray
    speed_m_s: np.ndarray
    amplitude_n: np.ndarray
    duration_s: np.ndarray
    duration_amplitude_n: np.ndarray
    peak_forces_n: np.ndarray
    restitution: np.ndarray
    c_theory: float
    c_numeric: float
    c_numeric_stderr: float
    c_numeric_exponent: float
    c_numeric_fit_amplitude: float
    c_apparent_damped: float
    duration_over_theory: float
    duration_converged: np.ndarray  # (n_velocities, 2, 2) whether each duration's cos^6 fit converged
    cos6_fits_converged: int  # of `cos6_fits`, durations and fitted amplitudes together
    cos6_fits: int
    broadening: np.ndarray  # (n_velocities,) 2tau(eta)/2tau(0) at the same amplitude
    viscous_fit: pulses.RestitutionFit
    friction_fit: pulses.RestitutionFit
    joint_fit: pulses.RestitutionFit
    c_v_paper_conversion: float  # the paper's 5 C eta / (2 sqrt(10) R) for eta
    c_s_paper_conversion: float  # the paper's 5 mu m g / 4 for mu
    eta_for_paper_c_v_s: float  # eta that gives the paper's C_v in this model (linear)
    mu_for_paper_c_s: float


def measure_fig2(sweep: Sweep) -> Fig2:
    """Speed, duration and restitution against amplitude, from the sweep."""
    plan, setup, time = sweep.plan, sweep.setup, sweep.time_s
    radius = float(setup.bead_radius_m[0])
    mass = float(setup.bead_mass_kg[0])
    velocities = np.asarray(plan.velocities_m_s, dtype=float)
    speed, amplitude = _incident(time, _stack_sweep(sweep, SPEED_CONTACTS), radius)
    peaks = _first_peaks(time, _stack_sweep(sweep, RESTITUTION_CONTACTS))
    peak_time, peak = (_np(a) for a in peaks)
    at_duration = RESTITUTION_CONTACTS.index(DURATION_CONTACT)
    first_time, first_force = peak_time[..., at_duration], peak[..., at_duration]
    # Restitution at contacts 6-17, normalised by the dissipationless run.
    reference = np.broadcast_to(peak[:, :1, :1, :], peak.shape)
    restitution = _np(pulses.restitution_coefficients(peak, reference))
    incoming = peak[..., :-1]
    # cos^6 fits in one call: the first pulse at contact 10 of every run (duration), and at
    # contacts 8-15 of the dissipationless runs (fitted amplitude, for the other C).
    width = _np(theory.solitary_duration_s(radius, speed))
    speed_index = [RESTITUTION_CONTACTS.index(k) for k in SPEED_CONTACTS]
    traces = np.concatenate([
        sweep.contact_n[DURATION_CONTACT].reshape(-1, len(time)),
        _stack_sweep(sweep, SPEED_CONTACTS)[:, 0, 0].reshape(-1, len(time)),
    ])
    centers = np.concatenate([first_time.ravel(), peak_time[:, 0, 0][:, speed_index].ravel()])
    half_widths = 2.0 * np.concatenate([
        width.ravel(), np.repeat(width[:, 0, 0], len(SPEED_CONTACTS)),
    ])
    fits = _fit_first_pulses(time, traces, centers, half_widths)
    n_runs = first_time.size
    duration_converged = _np(fits.converged)[:n_runs].reshape(first_time.shape).astype(bool)
    # a duration whose cos^6 fit did not converge is left out (NaN), not plotted or averaged
    duration = np.where(duration_converged, _np(fits.duration_s)[:n_runs].reshape(first_time.shape), np.nan)
    amplitude_converged = _np(fits.converged)[n_runs:].reshape(len(velocities), len(SPEED_CONTACTS)).astype(bool)
    fit_amplitudes = np.where(amplitude_converged,
                              _np(fits.peak_force_n)[n_runs:].reshape(len(velocities), len(SPEED_CONTACTS)), np.nan)

    elastic = (slice(None), 0, 0)
    law = pulses.fit_velocity_law(amplitude[elastic], speed[elastic])
    damped = pulses.fit_velocity_law(amplitude[:, 1, 0], speed[:, 1, 0])
    # C with the cos^6-fit amplitude instead of the peak (the other common definition).
    fit_amplitudes = np.nanmean(fit_amplitudes, axis=-1)
    law_fit_amplitude = pulses.fit_velocity_law(np.asarray(fit_amplitudes), speed[elastic])
    c_theory = float(theory.long_wave_velocity_constant(
        radius, float(setup.bead_density_kg_m3[0]), float(setup.bead_youngs_pa[0]),
        float(setup.bead_poisson[0]),
    ))
    ratio = duration[elastic] / _np(theory.solitary_duration_s(radius, speed[elastic]))
    # 2 tau of the dissipationless chain scales exactly as F^(-1/6): compare at equal force.
    elastic_scale = np.nanmean(duration[elastic] * first_force[elastic] ** (1.0 / 6.0))
    broadening = duration[:, 1, 0] / (elastic_scale * first_force[:, 1, 0] ** (-1.0 / 6.0))

    viscous = pulses.fit_restitution_law(
        incoming[:, 1, 0], restitution[:, 1, 0], friction=False,
        velocity_constant=law.velocity_constant, bead_radius_m=radius,
    )
    friction = pulses.fit_restitution_law(
        incoming[:, 0, 1], restitution[:, 0, 1], viscous=False, bead_mass_kg=mass,
    )
    joint = pulses.fit_restitution_law(
        incoming[:, 1, 1], restitution[:, 1, 1], velocity_constant=law.velocity_constant,
        bead_radius_m=radius, bead_mass_kg=mass,
    )
    return Fig2(
        velocities_m_s=velocities,
        eta_s=np.array([0.0, plan.eta_s]),
        mu=np.array([0.0, plan.mu]),
        speed_m_s=speed,
        amplitude_n=amplitude,
        duration_s=duration,
        duration_amplitude_n=first_force,
        peak_forces_n=peak,
        restitution=restitution,
        c_theory=c_theory,
        c_numeric=law.velocity_constant,
        c_numeric_stderr=law.velocity_constant_stderr,
        c_numeric_exponent=law.exponent,
        c_numeric_fit_amplitude=law_fit_amplitude.velocity_constant,
        c_apparent_damped=damped.velocity_constant,
        duration_over_theory=float(np.nanmean(ratio)),
        duration_converged=duration_converged,
        cos6_fits_converged=int(np.sum(duration_converged) + np.sum(amplitude_converged)),
        cos6_fits=int(duration_converged.size + amplitude_converged.size),
        broadening=broadening,
        viscous_fit=viscous,
        friction_fit=friction,
        joint_fit=joint,
        c_v_paper_conversion=float(theory.c_v_from_eta(plan.eta_s, law.velocity_constant, radius)),
        c_s_paper_conversion=float(theory.c_s_from_mu(plan.mu, mass)),
        eta_for_paper_c_v_s=plan.eta_s * PAPER_C_V / viscous.c_v,
        mu_for_paper_c_s=plan.mu * PAPER_C_S / friction.c_s,
    )


# ---------------------------------------------------------------------------------------
# Fig. 3: the wall


@dataclasses.dataclass
class WallCase:
    """One wall: `name`, `youngs_pa`, `poisson`, the measured `force_ratio`
    (F_wall^max / F_m), Eq. 5 as the paper writes it (`ratio_eq5`) and with the real
    Poisson ratios (`ratio_eq5_nu`), the momentum check at contact 10
    (`momentum_ratio`, wall area / (incident + reflected area)), the reflected pulses at
    contact 10 and on the wall relative to F_m (`reflected`, `wall_pulses`), and the
    energy shares during the wall encounter (`min_kinetic_share`, `max_potential_share`,
    `max_wall_share`, of the impact energy)."""

    name: str
    youngs_pa: float
    poisson: float
    force_ratio: float
    ratio_eq5: float
    ratio_eq5_nu: float
    momentum_ratio: float
    reflected: list[float]
    reflected_delays_s: list[float]
    reflected_times_s: list[float]
    wall_pulses: list[float]
    min_kinetic_share: float
    max_potential_share: float
    max_wall_share: float


@dataclasses.dataclass
class Fig3:
    """Fig. 3: the paper's wall samples (plus the 5 GPa sample, the beads' steel and a
    rigid wall) and a continuous sweep of the wall modulus (Poisson ratio 0.3).

    `cases` by name; `sweep_pa`, `sweep_ratio` the continuous curve; `time_s`,
    `traces_n` name -> {"wall", "contact_10", "contact_15"} force traces for the soft
    and steel walls (Fig. 3b/c)."""

    cases: dict[str, WallCase]
    sweep_pa: np.ndarray
    sweep_ratio: np.ndarray
    time_s: np.ndarray
    traces_n: dict[str, dict[str, np.ndarray]]
    incident_n: float


def wall_materials() -> dict[str, tuple[float, float]]:
    """Wall name -> (Young's modulus Pa, Poisson ratio): the paper's samples, the 5 GPa
    sample, the beads' steel (the paper's bare sensor cap) and a rigid wall."""
    walls = {
        name: (MATERIALS[name].youngs_pa, MATERIALS[name].poisson) for name in PAPER_WALL_MATERIALS
    }
    walls["soft_5GPa"] = (PAPER_SOFT_WALL_PA, MATERIALS["soft_5GPa"].poisson)
    walls["steel"] = (BEAD_STEEL.youngs_pa, BEAD_STEEL.poisson)
    walls["rigid"] = (math.inf, BEAD_STEEL.poisson)
    return walls


def _wall_case(name, youngs, poisson, time, wall, contact10, f_m, wall_peak, energies, kappa):
    """Measure one wall's run; `energies` = (impact, kinetic, potential, wall elastic) J."""
    wall_setup = ChainSetup(wall_youngs_pa=youngs, wall_poisson=poisson)
    momentum = pulses.momentum_check(time, wall, contact10, noise_std_n=0.0)
    found = peaks.find_pulses(time, contact10, min_fraction=0.01, noise_std_n=0.0)
    reflected = [p for p in found if p.label != "incident"]
    on_wall = peaks.find_pulses(time, wall, channel="wall", min_fraction=0.01, noise_std_n=0.0)
    energy0, kinetic, potential, wall_energy = energies
    window = (time > 0.5e-3) & (time < 1.6e-3)  # the wall encounter
    return WallCase(
        name=name,
        youngs_pa=youngs,
        poisson=poisson,
        force_ratio=wall_peak / f_m,
        ratio_eq5=float(theory.wall_force_ratio_paper(BEAD_STEEL.youngs_pa, youngs)),
        ratio_eq5_nu=float(theory.wall_force_ratio(float(wall_setup.wall_kappa()), kappa)),
        momentum_ratio=momentum.ratio,
        reflected=[p.peak_force_n / f_m for p in reflected],
        reflected_delays_s=[p.peak_time_s - reflected[0].peak_time_s for p in reflected],
        reflected_times_s=[p.peak_time_s for p in reflected],
        wall_pulses=[p.peak_force_n / f_m for p in on_wall],
        min_kinetic_share=float(np.min(kinetic[window])) / energy0,
        max_potential_share=float(np.max(potential[window])) / energy0,
        max_wall_share=float(np.max(wall_energy[window])) / energy0,
    )


def measure_fig3(sweep: Sweep) -> Fig3:
    """Force ratios, momentum, secondary waves and energies at the wall from the wall runs."""
    runs, time = sweep.walls, sweep.time_s
    radius = float(sweep.setup.bead_radius_m[0])
    kappa = float(sweep.setup.contact_kappa()[1])
    incident = np.stack([runs.contact_n[k] for k in SPEED_CONTACTS], axis=-2)
    _, f_m = _incident(time, incident, radius)
    wall_peak = _np(jax.jit(peaks.refine_peak)(time, runs.wall_n)[1])
    cases = {}
    for i, name in enumerate(runs.names):
        energies = (float(runs.initial_energy_j[i]), runs.kinetic_j[i], runs.potential_j[i],
                    runs.wall_elastic_j[i])
        cases[name] = _wall_case(
            name, float(runs.youngs_pa[i]), float(runs.poisson[i]), time, runs.wall_n[i],
            runs.contact_n[FAR_CONTACT][i], float(f_m[i]), float(wall_peak[i]), energies, kappa,
        )
    shown = {}
    for name in ("soft_5GPa", "steel"):
        i = runs.names.index(name)
        shown[name] = {
            "wall": runs.wall_n[i], f"contact_{FAR_CONTACT}": runs.contact_n[FAR_CONTACT][i],
            "contact_15": runs.contact_n[15][i],
        }
    n_named = len(runs.names)
    return Fig3(
        cases=cases,
        sweep_pa=runs.youngs_pa[n_named:],
        sweep_ratio=wall_peak[n_named:] / f_m[n_named:],
        time_s=time,
        traces_n=shown,
        incident_n=float(f_m[runs.names.index("steel")]),
    )
