"""Diagnosis of effects with a threshold, a singular onset or two competing laws, on data
made outside the diagnosis's own generator (`fitting.hidden`):

- a static preload read by piezo (AC-coupled) sensors on 15 brass beads with a striker
  smaller than the beads, simulated by the diffrax reference solver, and files that do not
  say their channels are AC-coupled (as an independent generator writes them);
- (plasticity on the paper's chain: `tests/test_contact_plasticity_diagnosis.py`, data from
  an independent integrator with the diagnosis's contact law);
- embedded sensors read as the paper's filter form of Eq. 4 (the chain not affected by
  them), applied after the simulation;
- a linear dashpot and Kuwabara-Kono damping on the brass chain (diffrax data), each to be
  named as itself.

Every record has 0.5 % noise per channel, an 11-12 bit converter and 2 us sampling. Slow:
each is a whole diagnosis (30-80 s on 2 cores)."""

import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain as hc
from fitting.diagnosis import diagnose
from hertzchain.acquisition import Acquisition, acquire_trace
from hertzchain.io.tracefile import TraceFile, setup_header
from hertzchain.materials import BRASS
from hertzchain.reference import simulate_reference
from hertzchain.sensor import sensor_signal

# the records reach forces above the beads' nominal yield force: only the plasticity data
# are meant to show it
pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore::hertzchain.integrate.YieldWarning")]


def _record(setup, time_s, forces, seed, bits, **acquisition):
    setting = Acquisition(sample_interval_s=2e-6, bits=bits,
                          noise_std_n={n: 0.005 * float(np.ptp(f)) for n, f in forces.items()}, **acquisition)
    return acquire_trace(setup, np.asarray(time_s), forces, setting, seed=seed)


def test_preload_read_by_piezo_sensors_is_named_precompression():
    files = []
    for k, velocity in enumerate((0.05, 0.15, 0.5, 1.5)):
        setup = hc.ChainSetup(15, bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                              bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                              striker_radius_m=3e-3, striker_velocity_m_s=velocity, precompression_n=2.0)
        run = simulate_reference(setup, t_end_s=0.6e-3, sample_interval_s=0.25e-6, contacts=(5, 10), rtol=1e-9)
        forces = {n: np.asarray(run.forces_n[n]) for n in run.channel_names}
        trace = _record(setup, run.time_s, forces, k, 12, coupling="ac")
        header = {key: v for key, v in trace.header.items() if key not in ("precompression_n", "ac_channels")}
        files.append(TraceFile(header, trace.time_s, trace.channels, path=f"brass_{velocity}"))
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == ["precompression"]
    values = diagnosis.steps[0].values
    assert values["preload_n"] == pytest.approx(2.0, rel=0.2)
    assert values["preload_seen"] < 0.5  # the channels read changes of force only
    assert "AC-coupled" in diagnosis.conclusion and not diagnosis.misspecification


def test_filter_form_sensors_are_named_sensor_dynamics_alone():
    files = []
    for k, velocity in enumerate((0.1, 0.3, 0.8)):
        setup = hc.ChainSetup(21, striker_velocity_m_s=velocity)
        run = hc.simulate(setup, t_end_s=1.6e-3, sample_interval_s=0.25e-6, contacts=(5, 6, 10, 11))
        time = jnp.asarray(run.time_s)
        f = {n: np.asarray(run.forces_n[n]) for n in run.channel_names}
        forces = {f"contact_{b}": np.asarray(sensor_signal(time, f[f"contact_{b}"], f[f"contact_{b - 1}"],
                                                           beta=0.11, f0_hz=85e3)) for b in (6, 11)}
        forces["wall"] = f["wall"]
        trace = _record(setup, run.time_s, forces, k, 11)
        files.append(TraceFile(trace.header, trace.time_s, trace.channels, path=f"sensor_{velocity}"))
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == ["sensor_dynamics"]
    values = diagnosis.steps[0].values
    assert values["sensor_coupling"] < 0.2  # the filter form, not the split-bead mechanics
    assert values["sensor_beta"] == pytest.approx(0.11, rel=0.1)
    assert "filter form" in diagnosis.conclusion and not diagnosis.misspecification


@pytest.mark.parametrize("law, fields, expected", [
    ("dashpot", {"dashpot_n_s_m": 20.0}, "dashpot_damping"),
    ("kuwabara-kono", {"eta_s": 1e-6}, "viscous_damping"),
])
def test_competing_damping_laws_are_told_apart(law, fields, expected):
    """A linear dashpot and Kuwabara-Kono damping on 15 brass beads (diffrax data): each is
    named as itself, not as the other."""
    files = []
    for k, velocity in enumerate((0.05, 0.15, 0.5, 1.5)):
        setup = hc.ChainSetup(15, bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                              bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                              striker_radius_m=3e-3, striker_velocity_m_s=velocity, **fields)
        run = simulate_reference(setup, t_end_s=0.6e-3, sample_interval_s=0.25e-6, contacts=(5, 10), rtol=1e-9)
        forces = {n: np.asarray(run.forces_n[n]) for n in run.channel_names}
        trace = _record(setup, run.time_s, forces, k, 12)
        nominal = hc.ChainSetup(15, bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                                bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                                striker_radius_m=3e-3, striker_velocity_m_s=velocity)
        header = setup_header(nominal) | {k2: v for k2, v in trace.header.items() if k2.startswith("noise_std")}
        files.append(TraceFile(header, trace.time_s, trace.channels, path=f"{law}_{velocity}"))
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == [expected]
    assert not diagnosis.misspecification


def test_contact_exponent_on_the_brass_chain():
    """n = 1.6 on 15 brass beads from the diffrax reference (normalised to Hertz at 3 um):
    named contact_exponent alone with n to 0.01."""
    files = []
    for k, velocity in enumerate((0.15, 0.5, 1.0, 1.5)):
        fields = dict(bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3, bead_youngs_pa=BRASS.youngs_pa,
                      bead_poisson=BRASS.poisson, striker_radius_m=3e-3, striker_velocity_m_s=velocity)
        setup = hc.ChainSetup(15, contact_exponent=1.6, exponent_reference_overlap_m=3e-6, **fields)
        run = simulate_reference(setup, t_end_s=0.7e-3, sample_interval_s=0.25e-6, contacts=(5, 10), rtol=1e-9)
        forces = {n: np.asarray(run.forces_n[n]) for n in run.channel_names}
        trace = _record(setup, run.time_s, forces, k, 12)
        header = setup_header(hc.ChainSetup(15, **fields)) | {
            key: v for key, v in trace.header.items() if key.startswith("noise_std")}
        files.append(TraceFile(header, trace.time_s, trace.channels, path=f"brass_{velocity}"))
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == ["contact_exponent"]
    assert 1.5 + diagnosis.steps[0].values["exponent_shift"] == pytest.approx(1.6, abs=0.01)
    assert not diagnosis.misspecification
