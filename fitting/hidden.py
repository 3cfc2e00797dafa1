"""Synthetic trace files with a known missing effect hidden in them (tests, benchmarks).

The data are simulated with the effect switched on (the "truth") and sampled as a recording
with a trigger offset sees them (`fitting.synthetic.sampled_clean`: a finer time step and
sampling than a diagnosis uses), and written with the header of the *nominal* chain (the
base model's view: no dissipation, ideal force sensors, the header's wall and beads). Each
file gets its own striker-velocity error in the header, a trigger offset, and white
Gaussian noise of a given fraction of its largest signal.

How each effect is hidden (`NOMINAL` holds the default strengths; `truth_fields` makes the
changes):

- `viscous_damping`: `eta_s` (s); `dashpot_damping`: `dashpot_n_s_m` (N s/m);
  `track_friction`: `mu`; `rotational_friction`: `mu_star`;
- `sensor_dynamics`: (`sensor_beta`, `sensor_f0_hz`): every `contact_K` channel is the
  signal of a sensor embedded in bead K (the core's split-bead model), a different code path
  from the diagnosis's compliance form of the same mechanics;
- `wall_compliance`: the wall's Young's modulus (Pa) differs from the header's;
- `bead_dispersion`: bead radii scattered by this relative standard deviation (fixed per
  data set, density fixed, so masses scatter three times as much);
- `precompression`: a static preload (N);
- `contact_exponent`: (n, $\\delta_r$ in m): power-law contacts
  $F = \\kappa\\delta_r^{3/2}(\\delta/\\delta_r)^n$, Hertz's force at the overlap $\\delta_r$;
- `plasticity`: elastic-plastic contacts (`contact.jackson_green_contact`) with this yield stress (Pa).
"""

from __future__ import annotations

import numpy as np

from hertzchain import laws
from hertzchain.chain import ChainSetup
from hertzchain.theory import wave_amplitude_n
from hertzchain.tracefile import TraceFile, setup_header

from .effects import EFFECT_NAMES
from .parameters import bare_speed_constant
from .synthetic import sampled_clean

NOMINAL = {
    "viscous_damping": 1e-6,
    "dashpot_damping": 20.0,
    "track_friction": 0.19,
    "rotational_friction": 0.03,
    "sensor_dynamics": (0.11, 85e3),
    "wall_compliance": 20e9,
    "bead_dispersion": 0.005,
    "precompression": 2.0,
    "contact_exponent": (1.6, 5e-6),
    # contacts between the paper's beads leave Hertz (`contact.jackson_green_yield_force`) at 470 N
    "plasticity": 1.34e9,
}
DEFAULT_VELOCITIES_M_S = (0.02, 0.05, 0.12, 0.3, 0.6)


def truth_fields(nominal: ChainSetup, hidden: dict, rng: np.random.Generator) -> dict:
    """`ChainSetup` keyword changes that turn the `nominal` chain into the true one.

    `hidden`: effect identifier -> strength (units in the module docstring); `rng` draws
    the bead scatter of `bead_dispersion`. What an effect is in the core's model is stated
    here once, for these files and for the benchmarks' independent generator.
    """
    changes: dict = {}
    for name, value in hidden.items():
        if name == "viscous_damping":
            changes["eta_s"] = value
        elif name == "dashpot_damping":
            changes["dashpot_n_s_m"] = value
        elif name == "track_friction":
            changes["mu"] = value
        elif name == "rotational_friction":
            changes["mu_star"] = value
        elif name == "wall_compliance":
            changes["wall_youngs_pa"] = value
        elif name == "bead_dispersion":
            scatter = np.clip(rng.standard_normal(nominal.n_beads), -2.5, 2.5)
            changes["bead_radius_m"] = np.asarray(nominal.bead_radius_m) * (1.0 + value * scatter)
            changes["bead_density_kg_m3"] = np.asarray(nominal.bead_density_kg_m3)
            changes["striker_radius_m"] = float(nominal.striker_radius_m)
        elif name == "precompression":
            changes["precompression_n"] = value
        elif name == "contact_exponent":
            changes["contact_law"] = laws.PowerLaw(*value)
        elif name == "plasticity":
            changes["contact_law"] = laws.JacksonGreen()
            changes["bead_yield_stress_pa"] = value
        elif name == "sensor_dynamics":
            changes["sensor_beta"], changes["sensor_f0_hz"] = value
        else:
            raise ValueError(f"hidden: unknown effect {name!r}; effects: {', '.join(EFFECT_NAMES)}.")
    return changes


def default_record_s(setup: ChainSetup, velocity_m_s: float, factor: float = 1.35) -> float:
    """Record length: `factor` x the time the pulse of the slowest shot takes to reach the wall, s."""
    kappa = float(setup.contact_kappa()[min(1, setup.n_beads - 1)])
    mass = float(setup.bead_mass_kg[0])
    amplitude = wave_amplitude_n(velocity_m_s, kappa, mass)
    speed = float(bare_speed_constant(setup)) * amplitude ** (1 / 6)
    return factor * setup.n_beads * 2 * float(setup.bead_radius_m[0]) / speed


def hidden_effect_traces(hidden=(), *, n_beads: int = 21, velocities_m_s=DEFAULT_VELOCITIES_M_S,
                         contacts=(7, 14), t_end_s: float | None = None, sample_interval_s: float = 1e-6,
                         noise_fraction: float = 0.005, velocity_error: float = 0.02,
                         trigger_jitter_s: float = 1e-6, seed: int = 0, **setup_fields) -> list[TraceFile]:
    """Trace files of a chain with the `hidden` effects, headers of the nominal chain.

    **Arguments:**

    - `hidden`: effect identifiers (nominal strengths, `NOMINAL`) or a dict identifier ->
      strength (see the module docstring for units).
    - `n_beads`, `setup_fields`: the nominal chain (`ChainSetup` keywords, e.g.
      `bead_radius_m`); `velocities_m_s`: one file per impact velocity.
    - `contacts`: recorded contacts (the wall is always recorded).
    - `t_end_s`: record length (default: `default_record_s` of the slowest shot).
    - `sample_interval_s`; `noise_fraction`: noise sigma / the file's largest signal.
    - `velocity_error`: relative standard deviation of the header's striker velocity.
    - `trigger_jitter_s`: standard deviation of the trigger offset.
    - `seed`: seeds noise, offsets, velocity errors and bead scatter.
    """
    for name in hidden:
        if name not in EFFECT_NAMES:
            raise ValueError(f"hidden: unknown effect {name!r}; effects: {', '.join(EFFECT_NAMES)}.")
    if not isinstance(hidden, dict):
        hidden = {name: NOMINAL[name] for name in hidden}
    rng = np.random.default_rng(seed)
    contacts = tuple(contacts)
    nominal = [ChainSetup(n_beads, striker_velocity_m_s=v, **setup_fields) for v in velocities_m_s]
    changes = truth_fields(nominal[0], hidden, rng)
    sensor_beads = tuple(k for k in contacts if k >= 1) if "sensor_dynamics" in hidden else ()
    if sensor_beads:
        changes["sensor_beads"] = sensor_beads
    truth = [ChainSetup(n_beads, striker_velocity_m_s=v, **(setup_fields | changes)) for v in velocities_m_s]
    if t_end_s is None:
        t_end_s = default_record_s(nominal[0], float(min(velocities_m_s)))
    offsets = trigger_jitter_s * rng.standard_normal(len(truth))
    time, clean = sampled_clean(truth, contacts=contacts, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                                time_offset_s=offsets)
    files = []
    for b, setup in enumerate(nominal):
        # a sensor bead's channel is its sensor's force
        ordered = {f"contact_{k}": clean[b][f"sensor_{k}" if k in sensor_beads else f"contact_{k}"]
                   for k in contacts}
        ordered["wall"] = clean[b]["wall"]
        sigma = noise_fraction * max(float(np.max(v)) for v in ordered.values())
        ordered = {name: value + sigma * rng.standard_normal(time.size) for name, value in ordered.items()}
        header = setup_header(setup)
        true_velocity = float(setup.striker_velocity_m_s)
        header["striker_velocity_m_s"] = true_velocity * (1.0 + velocity_error * rng.standard_normal())
        header["noise_std_n"] = sigma
        header["x_hidden_effects"] = "+".join(hidden) if hidden else "none"
        header["x_true_striker_velocity_m_s"] = repr(true_velocity)
        header["x_true_time_offset_s"] = repr(float(offsets[b]))
        for name, value in hidden.items():
            header[f"x_true_{name}"] = repr(value)
        files.append(TraceFile(header=header, time_s=time, channels=ordered, path=None))
    return files
