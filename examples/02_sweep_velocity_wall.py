# %% [markdown]
# # 2. Sweep impact velocity x wall modulus in one vmapped call
#
# `simulate_batch` runs the outer product of any scalar `ChainSetup` fields in one
# compiled, vmapped solve. Here: impact velocities x wall Young's moduli, and the ratio of
# the largest wall force to the incident solitary wave's amplitude (the paper's Fig. 3a),
# set beside the paper's estimate, Eq. 5.
#
# Set `HERTZCHAIN_EXAMPLE_SMALL=1` for a small grid; outputs go to `HERTZCHAIN_EXAMPLE_OUT`
# (default `out/examples`).

# %%
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import hertzchain as hc  # noqa: E402
from hertzchain import pulses, theory  # noqa: E402
from hertzchain.io.atomic import save_figure, write_text  # noqa: E402

SMALL = os.environ.get("HERTZCHAIN_EXAMPLE_SMALL") == "1"
OUT = Path(os.environ.get("HERTZCHAIN_EXAMPLE_OUT", "out/examples"))

velocities_m_s = [0.05, 0.3] if SMALL else [0.05, 0.1, 0.2, 0.3]
wall_youngs_pa = np.geomspace(3e9, 400e9, 3 if SMALL else 10)

# %% [markdown]
# One call; the result has leading axes (velocity, wall modulus). The wall keeps the
# beads' Poisson ratio (0.3). Contacts 8-15 are recorded to measure the incident wave.

# %%
contacts = tuple(range(8, 16))
batch = hc.simulate_batch(
    hc.ChainSetup(), t_end_s=2.2e-3,
    sample_interval_s=1e-6, contacts=contacts,
    striker_velocity_m_s=velocities_m_s, wall_youngs_pa=wall_youngs_pa,
)
time_s = np.asarray(batch.time_s).reshape(-1, batch.time_s.shape[-1])[0]
print("wall force array:", batch.forces_n["wall"].shape)

# %% [markdown]
# Incident amplitude: the mean parabolic peak force at contacts 8-15
# (`pulses.incident_wave`); wall force: the parabolic peak of the wall trace.

# %%
ratio = np.zeros((len(velocities_m_s), len(wall_youngs_pa)))
for i in range(len(velocities_m_s)):
    for j in range(len(wall_youngs_pa)):
        forces = np.stack([np.asarray(batch.forces_n[f"contact_{k}"][i, j]) for k in contacts])
        incident = pulses.incident_wave(time_s, forces, contacts, bead_radius_m=0.013)
        _, wall_peak = pulses.refine_peak(time_s, np.asarray(batch.forces_n["wall"][i, j]))
        ratio[i, j] = float(wall_peak) / incident.peak_force_n
estimate = np.asarray(theory.wall_force_ratio_paper(203e9, wall_youngs_pa))
for y, r, e in zip(wall_youngs_pa, ratio[-1], estimate):
    print(f"Y_wall = {y / 1e9:7.1f} GPa: F_wall/F_incident = {r:.4f}, Eq. 5 = {e:.4f} "
          f"({e / r - 1:+.1%})")
print("spread over impact velocities (the ratio is amplitude independent):",
      f"{np.max(np.ptp(ratio, axis=0)):.1e}")

# %%
figure, axis = plt.subplots(figsize=(6.5, 4.5))
for i, v in enumerate(velocities_m_s):
    axis.plot(wall_youngs_pa / 1e9, ratio[i], "o-", ms=4, label=f"simulation, {v:g} m/s")
axis.plot(wall_youngs_pa / 1e9, estimate, "k--", label="Eq. 5 of the paper")
axis.set_xscale("log")
axis.set_xlabel("wall Young's modulus (GPa)")
axis.set_ylabel("largest wall force / incident amplitude")
axis.set_title("the curves of all impact velocities coincide", fontsize=10)
axis.legend()
figure.tight_layout()
save_figure(figure, OUT / "02_force_ratio.png", dpi=110)
lines = ["striker_velocity_m_s,wall_youngs_pa,force_ratio,force_ratio_eq5"]
lines += [f"{v:g},{y:.6g},{ratio[i, j]:.6f},{estimate[j]:.6f}"
          for i, v in enumerate(velocities_m_s) for j, y in enumerate(wall_youngs_pa)]
write_text(OUT / "02_force_ratio.csv", "\n".join(lines) + "\n")
print(f"wrote {OUT / '02_force_ratio.png'} and {OUT / '02_force_ratio.csv'}")
