"""`reproduce`: regenerate the paper's figures and numbers into one folder.

Writes (all atomically):

- `fig1.png`, `fig1.csv`: embedded sensor and deconvolution, contact and wall forces,
  energies (0.3 m/s, eta = 0 and 2 us);
- `fig2.png`, `fig2_speed_duration.csv`, `fig2_restitution.csv`: speed, duration and
  restitution against amplitude (dissipationless, eta = 2 us, mu = 0.19, both);
- `fig3.png`, `fig3_walls.csv`, `fig3_sweep.csv`, `fig3_traces.csv`: wall force ratio
  against wall modulus, and the 5 GPa and steel walls' traces;
- `numbers.json`, `numbers.md`: every number beside the paper's.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..io.atomic import save_figure, write_csv, write_json, write_text
from ..progress import Progress
from . import experiments, figures
from .experiments import FAR_CONTACT, FULL_PLAN, QUICK_PLAN, SENSOR_BEAD, Plan
from .numbers import build_numbers, numbers_markdown


def _write_csv(path: Path, columns: dict) -> None:
    """Columns of equal length (numbers or strings) as a CSV file with a header line."""
    formatted = [
        [value if isinstance(value, str) else f"{float(value):.10g}" for value in column]
        for column in columns.values()
    ]
    write_csv(path, list(columns), zip(*formatted, strict=True))


def _save(figure, path: Path) -> None:
    save_figure(figure, path, dpi=110)
    plt.close(figure)


def _fig1_files(out: Path, fig1, sensor) -> None:
    _write_csv(out / "fig1.csv", {
        "time_s": fig1.time_s,
        f"contact_{FAR_CONTACT}_n_eta0": fig1.contact_n[0],
        f"contact_{FAR_CONTACT}_n_eta2us": fig1.contact_n[1],
        "wall_n_eta0": fig1.wall_n[0],
        "wall_n_eta2us": fig1.wall_n[1],
        "kinetic_j_eta2us": fig1.kinetic_j[1],
        "potential_j_eta2us": fig1.potential_j[1],
        "dissipated_j_eta2us": fig1.dissipated_j[1],
        "kinetic_j_eta0": fig1.kinetic_j[0],
        "potential_j_eta0": fig1.potential_j[0],
        f"sensor_{SENSOR_BEAD}_n_eta2us": sensor.sensor_n[1],
        f"sensor_{SENSOR_BEAD}_deconvolved_n_eta2us": sensor.deconvolved_n[1],
        "sensor_bead_front_contact_n_eta2us": sensor.front_n[1],
        "sensor_run_wall_n_eta2us": sensor.wall_n[1],
    })
    _save(figures.figure1(fig1, sensor, sensor.deconvolved_n[1]), out / "fig1.png")


def _fig2_files(out: Path, fig2) -> None:
    rows = {k: [] for k in ("striker_velocity_m_s", "eta_s", "mu", "amplitude_n", "speed_m_s",
                            "duration_amplitude_n", "duration_s")}
    restitution = {k: [] for k in ("striker_velocity_m_s", "eta_s", "mu", "contact", "force_n",
                                   "restitution")}
    for index in np.ndindex(fig2.speed_m_s.shape):
        i, j, k = index
        rows["striker_velocity_m_s"].append(fig2.velocities_m_s[i])
        rows["eta_s"].append(fig2.eta_s[j])
        rows["mu"].append(fig2.mu[k])
        rows["amplitude_n"].append(fig2.amplitude_n[index])
        rows["speed_m_s"].append(fig2.speed_m_s[index])
        rows["duration_amplitude_n"].append(fig2.duration_amplitude_n[index])
        rows["duration_s"].append(fig2.duration_s[index])
        for c, contact in enumerate(experiments.RESTITUTION_CONTACTS[:-1]):
            restitution["striker_velocity_m_s"].append(fig2.velocities_m_s[i])
            restitution["eta_s"].append(fig2.eta_s[j])
            restitution["mu"].append(fig2.mu[k])
            restitution["contact"].append(contact)
            restitution["force_n"].append(fig2.peak_forces_n[index][c])
            restitution["restitution"].append(fig2.restitution[index][c])
    _write_csv(out / "fig2_speed_duration.csv", rows)
    _write_csv(out / "fig2_restitution.csv", restitution)
    _save(figures.figure2(fig2), out / "fig2.png")


def _fig3_files(out: Path, fig3) -> None:
    cases = list(fig3.cases.values())
    _write_csv(out / "fig3_walls.csv", {
        "wall": [c.name for c in cases],
        "youngs_pa": [c.youngs_pa if math.isfinite(c.youngs_pa) else "inf" for c in cases],
        "poisson": [c.poisson for c in cases],
        "force_ratio": [c.force_ratio for c in cases],
        "force_ratio_eq5": [c.ratio_eq5 for c in cases],
        "force_ratio_eq5_nu": [c.ratio_eq5_nu for c in cases],
        "eq5_over_simulation_minus_1": [c.ratio_eq5 / c.force_ratio - 1.0 for c in cases],
        "momentum_ratio": [c.momentum_ratio for c in cases],
        "reflected_primary": [c.reflected[0] for c in cases],
        "reflected_secondary": [c.reflected[1] if len(c.reflected) > 1 else 0.0 for c in cases],
    })
    if len(fig3.sweep_pa):
        from .. import theory

        _write_csv(out / "fig3_sweep.csv", {
            "wall_youngs_pa": fig3.sweep_pa,
            "force_ratio": fig3.sweep_ratio,
            "force_ratio_eq5": np.asarray(theory.wall_force_ratio_paper(203e9, fig3.sweep_pa)),
        })
    columns = {"time_s": fig3.time_s}
    for name, traces in fig3.traces_n.items():
        for channel, values in traces.items():
            columns[f"{name}_{channel}_n"] = values
    _write_csv(out / "fig3_traces.csv", columns)
    _save(figures.figure3(fig3), out / "fig3.png")


def reproduce(
    out_dir, *, quick: bool = False, plan: Plan | None = None, progress: bool = True
) -> dict:
    """Regenerate the paper's simulation results into `out_dir` and return the numbers.

    **Arguments:**

    - `out_dir`: folder for the figures (PNG), their data (CSV) and `numbers.json` /
      `numbers.md`; created if missing.
    - `quick`: a reduced run (three impact velocities, no continuous wall sweep) for tests;
      the same quantities, with the amplitude-independent ones unchanged.
    - `plan`: an explicit `experiments.Plan` instead of the full or quick one.
    - `progress`: report the stages on stderr.

    **Returns:** the dict written to `numbers.json`.
    """
    plan = plan or (QUICK_PLAN if quick else FULL_PLAN)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stages = Progress(8, "reproduce (stages)") if progress else None
    started = time.perf_counter()

    def step():
        if stages is not None:
            stages.advance(1)

    sweep = experiments.run_sweep(plan)
    step()
    fig1 = experiments.measure_fig1(sweep)
    fig2 = experiments.measure_fig2(sweep)
    step()
    fig3 = experiments.measure_fig3(sweep)
    step()
    sensor = experiments.run_sensor(plan)
    step()
    _fig1_files(out, fig1, sensor)
    step()
    _fig2_files(out, fig2)
    step()
    _fig3_files(out, fig3)
    step()
    numbers = build_numbers(plan, fig1, sensor, fig2, fig3, quick=quick)
    numbers["settings"]["run_time_s"] = time.perf_counter() - started
    write_json(out / "numbers.json", numbers)
    write_text(out / "numbers.md", numbers_markdown(numbers))
    step()
    return numbers
