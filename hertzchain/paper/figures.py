"""The paper's three figures drawn from the reproduction's records (matplotlib, Agg).

Each function takes the record of `experiments` and returns a `Figure`; nothing global.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .. import theory  # noqa: E402
from .constants import PAPER, PAPER_C_S, PAPER_C_V  # noqa: E402
from .experiments import FAR_CONTACT, SENSOR_BEAD, Fig1, Fig2, Fig3, SensorRun  # noqa: E402

_RADIUS_M = 0.013


def figure1(fig1: Fig1, sensor: SensorRun, deconvolved_n: np.ndarray | None = None):
    """Fig. 1: (a) the embedded sensor and the wall, (b) contact and wall forces, (c) energies;
    all for the paper's chain at 0.3 m/s with eta = 2 us (index 1 of the records)."""
    figure, (a, b, c) = plt.subplots(3, 1, figsize=(8.5, 10), sharex=True)
    ms = sensor.time_s * 1e3
    a.plot(ms, sensor.wall_n[1], color="k", lw=1.4, label="wall force")
    a.plot(ms, sensor.sensor_n[1], color="tab:orange", lw=1.2,
           label=f"sensor in bead {SENSOR_BEAD}: raw signal $F_s$")
    a.plot(ms, sensor.front_n[1], "--", color="tab:blue", lw=1.2,
           label=f"true force at its front contact ({SENSOR_BEAD})")
    if deconvolved_n is not None:
        a.plot(ms, deconvolved_n, ":", color="tab:red", lw=1.6,
               label="$F_s$ deconvolved (Eq. 4, FFT)")
    a.set_ylabel("force (N)")
    a.set_title(
        f"(a) embedded sensor (beta = 0.11, f0 = 85 kHz): raw peak = "
        f"{sensor.peak_ratio_damped:.3f} x true peak", fontsize=10,
    )
    a.legend(fontsize=8, loc="upper left")

    ms = fig1.time_s * 1e3
    b.plot(ms, fig1.contact_n[1], color="tab:blue", lw=1.3,
           label=f"contact {FAR_CONTACT}, eta = 2 us (incident, then reflected)")
    b.plot(ms, fig1.wall_n[1], color="k", lw=1.4, label="wall, eta = 2 us")
    b.plot(ms, fig1.contact_n[0], color="tab:blue", lw=0.8, alpha=0.4, label="dissipationless")
    b.plot(ms, fig1.wall_n[0], color="k", lw=0.8, alpha=0.4)
    b.set_ylabel("force (N)")
    b.set_title("(b) simulated contact force far from the wall and wall force", fontsize=10)
    b.legend(fontsize=8, loc="upper left")

    mj = 1e3
    c.plot(ms, fig1.kinetic_j[1] * mj, color="tab:red", label="kinetic, eta = 2 us")
    c.plot(ms, fig1.potential_j[1] * mj, color="tab:green", label="potential, eta = 2 us")
    c.plot(ms, fig1.dissipated_j[1] * mj, color="tab:gray", label="dissipated (viscous)")
    c.plot(ms, fig1.kinetic_j[0] * mj, color="tab:red", lw=0.8, alpha=0.35,
           label="kinetic, dissipationless")
    c.plot(ms, fig1.potential_j[0] * mj, color="tab:green", lw=0.8, alpha=0.35,
           label="potential, dissipationless")
    c.axhline(fig1.initial_energy_j * mj, color="k", lw=0.6, ls=":", label="impact energy")
    marks = ((fig1.wall_peak_time_s[1], " wall"), (fig1.ejection_time_s[1], " ejection"))
    for when, text in marks:
        if np.isfinite(when):
            c.axvline(when * 1e3, color="k", lw=0.6, ls="--")
            c.text(when * 1e3, 0.55 * fig1.initial_energy_j * mj, text, fontsize=8)
    c.set_ylabel("energy (mJ)")
    c.set_xlabel("time since impact (ms)")
    c.set_title(
        f"(c) energies, eta = 2 us; travelling wave: kinetic share {fig1.kinetic_fraction:.4f} "
        f"(paper: about 0.56)", fontsize=10,
    )
    c.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(0.05, 0.96), ncol=2)
    figure.suptitle("Fig. 1: 21 steel beads, striker 0.3 m/s, steel wall", fontsize=11)
    figure.tight_layout()
    return figure


def figure2(fig2: Fig2):
    """Fig. 2: (a) speed and (b) duration against amplitude, (c) restitution."""
    figure, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.8))
    force = np.geomspace(3.0, 600.0, 200)
    el, damped = (slice(None), 0, 0), (slice(None), 1, 0)
    a.plot(force, fig2.c_theory * force ** (1 / 6), "k-", lw=1,
           label=f"theory, Eq. 3: C_t = {fig2.c_theory:.1f}")
    a.plot(force, fig2.c_numeric * force ** (1 / 6), "b--", lw=1,
           label=f"fit to simulation: C_n = {fig2.c_numeric:.2f} (paper 201.5)")
    a.plot(force, PAPER["C_experiment"].value * force ** (1 / 6), ":", color="tab:gray",
           label="paper's experimental fit C_e = 203.6")
    a.plot(fig2.amplitude_n[el], fig2.speed_m_s[el], "bo", ms=5,
           label="simulation, dissipationless")
    a.plot(fig2.amplitude_n[damped], fig2.speed_m_s[damped], "rs", ms=5, mfc="none",
           label="simulation, eta = 2 us")
    a.set_xscale("log")
    a.set_xlabel("amplitude $F_m$ (N)")
    a.set_ylabel("speed v (m/s)")
    a.set_title("(a) speed of the solitary wave", fontsize=10)
    a.legend(fontsize=7.5)

    b.plot(force, 1e6 * theory.solitary_duration_s(_RADIUS_M, fig2.c_theory * force ** (1 / 6)),
           "k-", lw=1, label="theory, Eq. 3: 2 tau = 2R sqrt(10)/v")
    b.plot(fig2.duration_amplitude_n[el], 1e6 * fig2.duration_s[el], "bo", ms=5,
           label=f"dissipationless ({fig2.duration_over_theory:.3f} x theory)")
    b.plot(fig2.duration_amplitude_n[damped], 1e6 * fig2.duration_s[damped], "rs", ms=5, mfc="none",
           label=f"eta = 2 us ({fig2.broadening[-1]:.3f} x dissipationless at the same force)")
    b.set_xscale("log")
    b.set_xlabel(f"amplitude at contact {FAR_CONTACT} (N)")
    b.set_ylabel("duration 2 tau (us)")
    b.set_title("(b) duration of the solitary wave (cos^6 fit)", fontsize=10)
    b.legend(fontsize=7.5)

    incoming = fig2.peak_forces_n[..., :-1]
    styles = (((1, 0), "rs", "eta = 2 us", fig2.viscous_fit),
              ((0, 1), "g^", "mu = 0.19", fig2.friction_fit),
              ((1, 1), "mD", "eta = 2 us and mu = 0.19", fig2.joint_fit))
    for (i, j), style, label, fit in styles:
        c.plot(incoming[:, i, j].ravel(), fig2.restitution[:, i, j].ravel(), style, ms=3.5,
               mfc="none", alpha=0.7, label=f"simulation, {label}")
        c.plot(force, theory.restitution_law(force, fit.c_v, fit.c_s), style[0] + "-", lw=1,
               label=f"fit: C_v = {fit.c_v:.4f}, C_s = {fit.c_s:.3f}")
    c.plot(force, theory.restitution_law(force, PAPER_C_V, PAPER_C_S), ":", color="tab:gray",
           label="paper's experiment: C_v = 0.019, C_s = 0.17")
    c.plot(force, theory.restitution_law(force, fig2.c_v_paper_conversion, 0.0), "--",
           color="tab:orange", lw=1,
           label=f"paper's conversion of eta = 2 us: C_v = {fig2.c_v_paper_conversion:.4f}")
    c.set_xscale("log")
    c.set_ylim(0.9, 1.002)
    c.set_xlabel("force F at the incoming contact (N)")
    c.set_ylabel("restitution $(F_{k+1}/F_k)^{5/6}$")
    c.set_title("(c) restitution coefficient (normalised by the elastic chain)", fontsize=10)
    c.legend(fontsize=7, loc="lower center")
    figure.tight_layout()
    return figure


def figure3(fig3: Fig3):
    """Fig. 3: (a) wall force ratio against wall modulus, (b) 5 GPa and (c) steel wall traces."""
    figure = plt.figure(figsize=(14, 8.5))
    grid = figure.add_gridspec(2, 2, width_ratios=(1.1, 1))
    a = figure.add_subplot(grid[:, 0])
    b = figure.add_subplot(grid[0, 1])
    c = figure.add_subplot(grid[1, 1], sharex=b)
    youngs = np.geomspace(1e9, 3e12, 200)
    a.plot(youngs / 1e9, theory.wall_force_ratio_paper(203e9, youngs), "k--", lw=1,
           label=r"Eq. 5: $2^{6/5}(1 + Y_b/Y_w)^{-2/5}$")
    if len(fig3.sweep_pa):
        a.plot(fig3.sweep_pa / 1e9, fig3.sweep_ratio, "b-", lw=1.2,
               label="simulation (wall nu = 0.3)")
    finite = [case for case in fig3.cases.values() if np.isfinite(case.youngs_pa)]
    a.plot([cs.youngs_pa / 1e9 for cs in finite], [cs.force_ratio for cs in finite], "bo", ms=6,
           label="simulation, wall samples")
    a.plot([cs.youngs_pa / 1e9 for cs in finite], [cs.ratio_eq5_nu for cs in finite], "kx", ms=6,
           label="Eq. 5 with each sample's nu")
    below = {"steel", "Si"}  # labels placed under the curve where points crowd
    for cs in finite:
        offset = (2, -13) if cs.name in below else (-10, 7)
        a.annotate(cs.name.replace("_", " "), (cs.youngs_pa / 1e9, cs.force_ratio),
                   textcoords="offset points", xytext=offset, fontsize=8)
    rigid = fig3.cases.get("rigid")
    if rigid is not None:
        a.axhline(rigid.force_ratio, color="b", lw=0.6, ls=":")
        a.text(1.2, rigid.force_ratio + 0.02, f"rigid wall: {rigid.force_ratio:.3f} "
               f"(Eq. 5: {rigid.ratio_eq5:.3f})", fontsize=8, color="b")
    a.set_xscale("log")
    a.set_xlabel("wall Young's modulus $Y_w$ (GPa)")
    a.set_ylabel("$F_{wall}^{max} / F_{incident}^{max}$")
    a.set_title("(a) force ratio at the wall (striker 0.3 m/s, no dissipation)", fontsize=10)
    a.legend(fontsize=8, loc="lower right")

    ms = fig3.time_s * 1e3
    for axis, name, label in ((b, "soft_5GPa", "(b) 5 GPa wall"), (c, "steel", "(c) steel wall")):
        axis.set_xlabel("time since impact (ms)")
        traces = fig3.traces_n[name]
        axis.plot(ms, traces[f"contact_{FAR_CONTACT}"], color="tab:blue", lw=1.2,
                  label=f"contact {FAR_CONTACT}")
        axis.plot(ms, traces["contact_15"], color="tab:green", lw=1.0, label="contact 15")
        axis.plot(ms, traces["wall"], "k--", lw=1.3, label="wall")
        case = fig3.cases[name]
        secondary = case.reflected[1] if len(case.reflected) > 1 else 0.0
        axis.set_title(
            f"{label}; reflected at contact {FAR_CONTACT} (x incident): "
            f"{case.reflected[0]:.3f}, then {secondary:.3f}", fontsize=10,
        )
        if secondary > 0.1:
            when = case.reflected_times_s[1] * 1e3
            axis.annotate("secondary solitary wave", (when, secondary * fig3.incident_n),
                          xytext=(when + 0.25, secondary * fig3.incident_n + 90),
                          arrowprops=dict(arrowstyle="->", lw=0.8), fontsize=8)
        axis.set_ylabel("force (N)")
        axis.legend(fontsize=8, loc="upper right")
    figure.tight_layout()
    return figure
