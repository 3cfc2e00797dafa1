# %% [markdown]
# # 4. Diagnose a data set: which effect is the model missing?
#
# `fitting.diagnose` fits the stated model (the header's chain: no dissipation, ideal
# sensors), locates where the residual lives, tries every candidate effect of its library
# (viscous damping, track friction, thwarted rotation, sensor dynamics, wall compliance,
# bead dispersion, precompression, plasticity), and names one only if it removes a real
# share of the misfit and improves held-out traces. Then it repeats, or says nothing is
# missing.
#
# Here the data hide a softer wall than their header states (20 GPa instead of the beads'
# steel), with noise, a striker-velocity error and trigger jitter per shot.
#
# Set `HERTZCHAIN_EXAMPLE_SMALL=1` for a small data set; outputs go to
# `HERTZCHAIN_EXAMPLE_OUT` (default `out/examples`).

# %%
import os
from pathlib import Path

from fitting.diagnosis import diagnose
from fitting.diagnosis.report import write_diagnosis_report
from fitting.hidden import hidden_effect_traces
from hertzchain.io.tracefile import write_trace

SMALL = os.environ.get("HERTZCHAIN_EXAMPLE_SMALL") == "1"
OUT = Path(os.environ.get("HERTZCHAIN_EXAMPLE_OUT", "out/examples"))

# %% [markdown]
# ## The data: trace files whose header says "steel wall"

# %%
velocities_m_s = (0.05, 0.3) if SMALL else (0.02, 0.05, 0.12, 0.3, 0.6)
traces = hidden_effect_traces({"wall_compliance": 20e9}, velocities_m_s=velocities_m_s, seed=3)
paths = []
for velocity, trace in zip(velocities_m_s, traces):
    path = OUT / "04_data" / f"shot_{velocity:g}m_s.csv"
    write_trace(path, trace)
    paths.append(path)
print(f"{len(paths)} trace files, header wall modulus {traces[0].header['wall_youngs_pa']:.3g} Pa")

# %% [markdown]
# ## The diagnosis

# %%
# The small size screens three candidates and stops after the first named effect.
small = dict(candidates=("viscous_damping", "track_friction", "wall_compliance"), max_effects=1)
diagnosis = diagnose(paths, progress=False, **(small if SMALL else {}))
print("missing effects:", diagnosis.missing_effects or "none")
print(diagnosis.conclusion)

# %% [markdown]
# The report: `diagnosis.json` with every step and candidate, and plots of where the
# residual lives before and after.

# %%
write_diagnosis_report(diagnosis, OUT / "04_diagnosis")
print("wrote", OUT / "04_diagnosis")
