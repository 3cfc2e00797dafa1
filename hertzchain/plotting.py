"""Matplotlib figures of runs. Functions take data and return a Figure (no global state)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .traces import Traces  # noqa: E402


def plot_run(traces: Traces, *, title: str | None = None):
    """Forces at the recorded contacts and the wall (as the paper's Fig. 1b) over the
    energies (Fig. 1c): kinetic, potential, dissipated and their sum, all in J."""
    time_ms = np.asarray(traces.time_s) * 1e3
    figure, (forces, energies) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for name in traces.channel_names:
        style = dict(color="k", lw=1.6) if name == "wall" else dict(lw=1.2)
        forces.plot(time_ms, np.asarray(traces.forces_n[name]), label=name.replace("_", " "), **style)
    forces.set_ylabel("force (N)")
    forces.legend(loc="upper right", fontsize=9)
    forces.set_title(title or "contact and wall forces")
    energy0 = float(traces.initial_energy_j)
    energies.plot(time_ms, np.asarray(traces.kinetic_j) / energy0, label="kinetic")
    energies.plot(time_ms, np.asarray(traces.potential_j) / energy0, label="potential")
    if float(np.max(np.asarray(traces.dissipated_j))) > 0:
        energies.plot(time_ms, np.asarray(traces.dissipated_j) / energy0, label="dissipated")
    total = np.asarray(traces.mechanical_energy_j + traces.dissipated_j) / energy0
    energies.plot(time_ms, total, "k--", lw=1, label="sum")
    energies.set_xlabel("time since impact (ms)")
    energies.set_ylabel(f"energy / impact energy ({energy0 * 1e3:.3g} mJ)")
    energies.legend(loc="center right", fontsize=9)
    figure.tight_layout()
    return figure
