"""Records with a hidden effect made outside the diagnosis's own generator (`fitting.hidden`),
for the confusion table of `benchmarks/confusion.py --independent`.

What an effect and its strength change in the chain is taken from
`fitting.hidden.truth_fields` (the definition of the effect, not a code path under test);
everything else differs from that generator's: the solver, the sensors, the setups, the
acquisition and the files.

Two setups: the paper's chain (21 steel beads of 13 mm, an identical striker) and a brass
one (15 beads of 5 mm radius struck by a 3 mm brass ball). Two code paths: the diffrax
reference solver (adaptive Dopri8, `hertzchain.reference`; Coulomb friction there is its
tanh regularisation, plasticity is not available and falls back to the Verlet solver at
four times the diagnosis's steps), or the Verlet solver at 800 steps per contact. Embedded
sensors, when hidden, follow the paper's filter form of Eq. 4 applied after the
simulation (`hertzchain.sensor.sensor_signal`), not the split-bead mechanics the
diagnosis's compliance form is built on. Each record goes through `hertzchain.acquisition`:
0.5 % noise per channel, an 11-bit converter, 2 us sampling, piezo (AC-coupled) channels,
the header's striker velocity true and the trigger at the impact; the files do not state
their coupling (an independent generator's files do not), and the header describes the
nominal chain.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

import hertzchain as hc
from fitting.effects import nominal_yield_forces_n
from fitting.hidden import truth_fields
from hertzchain.acquisition import Acquisition, acquire
from hertzchain.io.tracefile import TraceFile, format_rows, setup_header
from hertzchain.materials import BEAD_STEEL, BRASS, GLASS
from hertzchain.reference import simulate_reference
from hertzchain.sensor import sensor_signal

SETUPS = {
    "paper": dict(n_beads=21, fields={}, contacts=(6, 11), velocities_m_s=(0.05, 0.12, 0.3, 0.6, 1.0),
                  record_s=1.7e-3, reference_overlap_m=5e-6),
    "brass": dict(n_beads=15, contacts=(5, 10), velocities_m_s=(0.05, 0.15, 0.5, 1.0, 1.5), record_s=0.7e-3,
                  reference_overlap_m=3e-6,
                  fields=dict(bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                              bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                              striker_radius_m=3e-3)),
    # 12 glass beads of 6 mm struck by a steel ball of 4 mm (the stopping rule's third setup)
    "glass": dict(n_beads=12, contacts=(4, 8), velocities_m_s=(0.05, 0.15, 0.5, 1.0, 1.5), record_s=0.8e-3,
                  reference_overlap_m=3e-6,
                  fields=dict(bead_radius_m=6e-3, bead_density_kg_m3=GLASS.density_kg_m3,
                              bead_youngs_pa=GLASS.youngs_pa, bead_poisson=GLASS.poisson, striker_radius_m=4e-3,
                              striker_density_kg_m3=BEAD_STEEL.density_kg_m3,
                              striker_youngs_pa=BEAD_STEEL.youngs_pa, striker_poisson=BEAD_STEEL.poisson)),
}
# Hidden strengths (SI); plasticity's is the yield force as a share of the largest force any
# bead-bead contact of the data set reaches elastically; contact_exponent's law equals
# Hertz's at the setup's `reference_overlap_m`.
STRENGTHS = {"viscous_damping": 1e-6, "dashpot_damping": 20.0, "track_friction": 0.19, "rotational_friction": 0.03,
             "sensor_dynamics": (0.11, 85e3), "wall_compliance": 20e9, "bead_dispersion": 0.005,
             "precompression": 2.0, "plasticity": 0.6, "contact_exponent": 1.6}


def _true_fields(setup_name: str, hidden, rng) -> dict:
    """The true chain's `ChainSetup` keywords: `fitting.hidden.truth_fields` (what each effect
    is in the core's model) for the strengths of this generator; embedded sensors are left out
    (applied after the simulation in the filter form)."""
    spec = SETUPS[setup_name]
    nominal = hc.ChainSetup(spec["n_beads"], **spec["fields"])
    strengths = {}
    for name in hidden:
        value = STRENGTHS[name]
        if name == "sensor_dynamics":
            continue
        if name == "contact_exponent":  # Hertz's force at an overlap typical of the setup
            value = (value, spec["reference_overlap_m"])
        elif name == "plasticity":  # the yield stress that gives the hidden yield force
            share = true_strength(setup_name, name) / float(nominal_yield_forces_n(nominal)[1])
            value = float(nominal.bead_yield_stress_pa) * share ** (1 / 3)
        strengths[name] = value
    return dict(spec["fields"]) | truth_fields(nominal, strengths, rng)


def true_strength(setup_name: str, effect: str) -> float:
    """The hidden strength of `effect` on `setup_name` as a physicist states it: the yield
    force of a bead-bead contact (N) for plasticity (`STRENGTHS` share of the largest elastic
    force at contact 2 of the fastest shot), the exponent n for contact_exponent, beta for
    sensor_dynamics, `STRENGTHS` (SI) for the others."""
    spec = SETUPS[setup_name]
    value = STRENGTHS[effect]
    if effect == "sensor_dynamics":
        return value[0]
    if effect == "plasticity":
        fastest = hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=max(spec["velocities_m_s"]),
                                **spec["fields"])
        peak = float(np.max(np.asarray(hc.simulate(fastest, t_end_s=spec["record_s"], contacts=(2,),
                                                   on_yield="ignore").forces_n["contact_2"])))
        return value * peak
    return value


def hidden_records(setup_name: str, hidden=(), *, code_path: str = "diffrax", seed: int = 0,
                   noise_fraction: float = 0.005, velocities_m_s=None) -> list[TraceFile]:
    """Records of `setup_name` (a key of `SETUPS`) with the `hidden` effects (identifiers of
    `fitting.effects`, strengths `STRENGTHS`) from `code_path` ("diffrax" or "verlet"), with
    noise of `noise_fraction` of each channel's peak, at the setup's impact velocities (or
    `velocities_m_s`, m/s)."""
    if code_path not in ("diffrax", "verlet"):
        raise ValueError(f"code_path must be 'diffrax' or 'verlet', got {code_path!r}.")
    spec = SETUPS[setup_name]
    rng = np.random.default_rng(seed)
    fields = _true_fields(setup_name, hidden, rng)
    sensor = "sensor_dynamics" in hidden
    contacts = spec["contacts"]
    simulated = tuple(sorted(set(contacts) | ({k - 1 for k in contacts} if sensor else set())))
    files = []
    for k, velocity in enumerate(spec["velocities_m_s"] if velocities_m_s is None else velocities_m_s):
        truth = hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=velocity, **fields)
        nominal = hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=velocity, **spec["fields"])
        if code_path == "diffrax" and not truth.plasticity:
            # (an elastic generator, as the Verlet path's below: a shot above the beads' yield
            # force is the data of an elastic chain, not of a yielding one)
            run = simulate_reference(truth, t_end_s=spec["record_s"], sample_interval_s=0.25e-6,
                                     contacts=simulated, rtol=1e-9, on_yield="ignore")
        else:
            run = hc.simulate(truth, t_end_s=spec["record_s"], sample_interval_s=0.25e-6, contacts=simulated,
                              steps_per_contact=800, on_yield="ignore")
        time = np.asarray(run.time_s)
        forces = {f"contact_{c}": np.asarray(run.forces_n[f"contact_{c}"]) for c in contacts}
        forces["wall"] = np.asarray(run.forces_n["wall"])
        if sensor:
            beta, f0_hz = STRENGTHS["sensor_dynamics"]
            for c in contacts:
                forces[f"contact_{c}"] = np.asarray(sensor_signal(
                    jnp.asarray(time), jnp.asarray(run.forces_n[f"contact_{c}"]),
                    jnp.asarray(run.forces_n[f"contact_{c - 1}"]), beta=beta, f0_hz=f0_hz))
        rest = float(truth.precompression_n)
        noise = {n: noise_fraction * float(np.max(f) - rest) for n, f in forces.items()}
        setting = Acquisition(sample_interval_s=2e-6, noise_std_n=noise, bits=11, coupling="ac")
        record = acquire(time, forces, setting, seed=1000 * seed + k, static_n=rest)
        header = setup_header(nominal)  # the nominal chain; the true impact velocity
        header["noise_std_n"] = max(record.noise_std_n.values())
        for name in record.channels:
            header[f"noise_std_n_{name}"] = record.noise_std_n[name]
            if record.clipped[name].any():
                header[f"clipped_{name}"] = format_rows(record.clipped[name])
        header["x_hidden_effects"] = "+".join(hidden) or "none"
        header["x_code_path"] = code_path
        files.append(TraceFile(header, record.time_s, record.channels, path=f"{setup_name}_{velocity:g}"))
    return files
