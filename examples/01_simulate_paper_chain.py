# %% [markdown]
# # 1. Simulate the paper's chain
#
# 21 steel beads (R = 13 mm), a striker identical to a bead at 0.3 m/s, a steel wall, and
# viscoelastic damping eta = 2 us: the setup of Fig. 1 of Job, Melo, Sokolow, Sen,
# PRL 94, 178002 (2005). We record a contact far from the wall and the wall force, check
# the energy and momentum books, plot the run and save it as a trace file.
#
# Set `HERTZCHAIN_EXAMPLE_SMALL=1` for a short run; outputs go to `HERTZCHAIN_EXAMPLE_OUT`
# (default `out/examples`).

# %%
import os
from pathlib import Path

import numpy as np

import hertzchain as hc
from hertzchain import plotting
from hertzchain.io.atomic import save_figure
from hertzchain.io.tracefile import TraceFile, setup_header, write_trace

SMALL = os.environ.get("HERTZCHAIN_EXAMPLE_SMALL") == "1"
OUT = Path(os.environ.get("HERTZCHAIN_EXAMPLE_OUT", "out/examples"))

# %% [markdown]
# A `ChainSetup` with no arguments is the paper's chain; every field is SI and carries its
# unit in its name.

# %%
setup = hc.ChainSetup(eta_s=2e-6)
print(f"kappa = {float(setup.contact_kappa()[1]) * 1e-9:.3f} N/um^1.5, "
      f"bead mass = {float(setup.bead_mass_kg[0]) * 1e3:.2f} g")

t_end_s = 1.5e-3 if SMALL else 2.5e-3
run = hc.simulate(setup, t_end_s=t_end_s, sample_interval_s=1e-6, contacts=(5, 10))

# %% [markdown]
# Peaks: the incident wave at contact 10 and the (much larger) wall force.

# %%
time_s = np.asarray(run.time_s)
for name in run.channel_names:
    force = np.asarray(run.forces_n[name])
    print(f"{name:>10}: peak {force.max():7.1f} N at {time_s[force.argmax()] * 1e3:.3f} ms")

energy_error = float(np.max(np.abs(np.asarray(run.energy_error_j)))) / float(run.initial_energy_j)
momentum_error = float(np.max(np.abs(np.asarray(run.momentum_balance_error_kg_m_s))))
print(f"energy books balance to {energy_error:.1e} of the impact energy, "
      f"momentum to {momentum_error:.1e} kg m/s")
print(f"dissipated by the viscous force: "
      f"{float(run.dissipated_viscous_j[-1]) / float(run.initial_energy_j):.1%}")

# %% [markdown]
# Forces (as the paper's Fig. 1b) over energies (Fig. 1c), and the traces as a
# `hertzchain-trace/1` CSV file that the other tools read.

# %%
figure = plotting.plot_run(run, title="the paper's chain, eta = 2 us")
save_figure(figure, OUT / "01_paper_chain.png", dpi=110)
write_trace(
    OUT / "01_paper_chain.csv",
    TraceFile(
        header=setup_header(setup),
        time_s=time_s,
        channels={name: np.asarray(run.forces_n[name]) for name in run.channel_names},
    ),
)
print(f"wrote {OUT / '01_paper_chain.png'} and {OUT / '01_paper_chain.csv'}")
