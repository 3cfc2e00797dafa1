# %% [markdown]
# # 6. Your own data: from oscilloscope files to η, μ, C and a diagnosis
#
# A lab's shots come off the scope in volts: a pre-trigger segment, a DC offset on each
# channel, 12-bit steps, the sensors' sensitivities in the notebook. Here a stand-in for the
# lab writes such files (the paper's chain with a sensor in bead 11 and the wall sensor,
# piezo channels, one CSV per shot with `time (ms), CH1 (mV), CH2 (mV)` columns); then the
# files are described in an `experiment.toml`, imported, fitted and diagnosed exactly as
# real recordings would be.
#
# Set `HERTZCHAIN_EXAMPLE_SMALL=1` for a small data set (a 10-bead chain, three shots);
# outputs go to `HERTZCHAIN_EXAMPLE_OUT` (default `out/examples`).

# %%
import csv
import os
from pathlib import Path

import numpy as np

import fitting
import hertzchain as hc
from fitting.diagnosis import diagnose
from fitting.diagnosis.report import write_diagnosis_report
from fitting.report import write_report
from hertzchain.acquisition import Acquisition, acquire
from hertzchain.io.importer import import_experiment

SMALL = os.environ.get("HERTZCHAIN_EXAMPLE_SMALL") == "1"
OUT = Path(os.environ.get("HERTZCHAIN_EXAMPLE_OUT", "out/examples")) / "06_scope_files"
OUT.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## The lab's files (a stand-in: simulated, then recorded as a scope would)

# %%
n_beads, sensor_bead = (10, 5) if SMALL else (21, 11)
velocities_m_s = (0.03, 0.1, 0.3) if SMALL else (0.03, 0.08, 0.15, 0.3)
truth = {"eta_s": 1.5e-6, "mu": 0.15}
sensitivity_v_per_n = {"CH1": 0.1124, "CH2": 0.01124}  # wall PCB 208A11, embedded PCB 200B02
measures = {"CH1": "wall", "CH2": f"sensor_{sensor_bead}"}
for shot, velocity in enumerate(velocities_m_s, start=1):
    setup = hc.ChainSetup(n_beads, sensor_beads=(sensor_bead,), striker_velocity_m_s=velocity, **truth)
    run = hc.simulate(setup, t_end_s=0.35e-3 + 0.11e-3 * n_beads, sample_interval_s=0.1e-6)
    forces = {source: np.asarray(run.forces_n[name]) for source, name in measures.items()}
    setting = Acquisition(
        sample_interval_s=1e-6, pre_trigger_samples=250, bits=12, coupling="ac",
        noise_std_n={s: 0.003 * float(np.max(f)) for s, f in forces.items()},
        sensitivity_v_per_n=sensitivity_v_per_n, dc_offset_v={"CH1": 0.012, "CH2": -0.004},
    )
    record = acquire(np.asarray(run.time_s), forces, setting, seed=shot)
    with open(OUT / f"shot{shot}.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time (ms)", "CH1 (mV)", "CH2 (mV)"])
        for k, t in enumerate(record.time_s):
            writer.writerow([f"{t * 1e3:.4f}", f"{record.volts['CH1'][k] * 1e3:.2f}",
                             f"{record.volts['CH2'][k] * 1e3:.2f}"])

# %% [markdown]
# ## The experiment file: what the lab notebook says

# %%
shots = "".join(f'\n[[shot]]\nfiles = ["shot{k}.csv"]\nstriker_velocity_m_s = {v}\n'
                for k, v in enumerate(velocities_m_s, start=1))
(OUT / "experiment.toml").write_text(f"""\
[chain]
n_beads = {n_beads}
bead_radius_m = "13mm"
bead_density_kg_m3 = 7780
bead_youngs_pa = 203e9
bead_poisson = 0.3
wall_youngs_pa = 203e9
wall_poisson = 0.3

[scope]
format = "csv"
time_zero = "trigger"

[[channel]]
source = "CH1"
measures = "wall"
sensitivity_v_per_n = 0.1124
coupling = "ac"

[[channel]]
source = "CH2"
measures = "sensor_{sensor_bead}"
sensitivity_v_per_n = 0.01124
coupling = "ac"
sensor_beta = 0.11
sensor_f0_hz = 85000
""" + shots)

# %% [markdown]
# ## Import: offsets, newtons, noise, time zero, each step in the header

# %%
traces = import_experiment(OUT / "experiment.toml")
for trace in traces:
    print(trace.header["x_shot"], {name: f"offset {float(trace.header[f'x_import_{name}_offset_v']) * 1e3:.2f} mV, "
                                         f"noise {trace.channel_noise_std_n(name):.3g} N"
                                   for name in trace.channels})

# %% [markdown]
# ## Fit η, μ and C to the recorded traces

# %%
result = fitting.fit(OUT / "experiment.toml", ("eta_s", "mu", "C"), progress=False)
write_report(result, OUT / "fit")
for name, true in (("eta_s", truth["eta_s"]), ("mu", truth["mu"])):
    print(f"{name} = {result.values[name]:.4g} +- {result.stderr[name]:.2g} (truth {true:g})")
print(f"C = {result.values['C']:.5g} +- {result.stderr['C']:.2g}, chi^2/dof = {result.reduced_chi2:.3f}")

# %% [markdown]
# ## Diagnose: which effects does the bare Hertz chain miss in these recordings?

# %%
small = dict(candidates=("viscous_damping", "track_friction", "wall_compliance"), max_effects=2)
diagnosis = diagnose(OUT / "experiment.toml", progress=False, **(small if SMALL else {}))
print("missing effects:", diagnosis.missing_effects or "none")
print(diagnosis.conclusion)
write_diagnosis_report(diagnosis, OUT / "diagnosis")
