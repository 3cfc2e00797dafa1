"""Machine-readable summary of one run: setup, stiffnesses, time step, peaks, balances."""

from __future__ import annotations

import numpy as np

from .chain import LAW_ATTRIBUTES, ChainSetup
from .timegrid import choose_time_grid, shortest_contact_time_s
from .traces import Traces


def _plain(value):
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        number = float(array)
        return number if np.isfinite(number) else str(number)
    return [_plain(item) for item in array]


def setup_dict(setup: ChainSetup) -> dict:
    """All fields of a setup as JSON-ready values (SI units, named as the fields)."""
    values = {
        "n_beads": setup.n_beads,
        "end": setup.end,
        "sensor_beads": list(setup.sensor_beads),
        "plasticity": setup.plasticity,
        "plastic_law": setup.plastic_law,
        "contact_law": type(setup.contact_law).__name__,
        "dissipation": {type(law).__name__: {field: _plain(getattr(law, field)) for field in law.__dataclass_fields__}
                        for law in setup.dissipation},
    }
    for name in (*ChainSetup.__dataclass_fields__, *LAW_ATTRIBUTES):
        if name not in values:
            values[name] = _plain(getattr(setup, name))
    values["bead_mass_kg"] = _plain(setup.bead_mass_kg)
    values["striker_mass_kg"] = _plain(setup.striker_mass_kg)
    return values


def run_summary(setup: ChainSetup, traces: Traces, options: dict) -> dict:
    """Summary of a run made with `simulate(setup, **options)`."""
    grid = choose_time_grid(
        setup, t_end_s=options["t_end_s"], sample_interval_s=options["sample_interval_s"],
        dt_s=options.get("dt_s"),
    )
    energy0 = float(traces.initial_energy_j)
    momentum_error = np.abs(np.asarray(traces.momentum_balance_error_kg_m_s))
    peaks = {name: float(np.max(np.asarray(traces.forces_n[name]))) for name in traces.channel_names}
    peak_times = {
        name: float(np.asarray(traces.time_s)[np.argmax(np.asarray(traces.forces_n[name]))])
        for name in traces.channel_names
    }
    return {
        "setup": setup_dict(setup),
        "kappa_n_per_m1p5": {
            "contacts": _plain(setup.contact_kappa()),
            "wall": _plain(setup.wall_kappa()) if setup.end == "wall" else None,
        },
        "kappa_n_per_um1p5": {
            "contacts": _plain(np.asarray(setup.contact_kappa()) * 1e-9),
            "wall": _plain(np.asarray(setup.wall_kappa()) * 1e-9) if setup.end == "wall" else None,
        },
        "yield_force_n": {
            "contacts": _plain(np.asarray(traces.yield_force_n)[:-1]),
            "wall": _plain(np.asarray(traces.yield_force_n)[-1]),
        },
        "time_step": {
            "dt_s": grid.dt_s,
            "steps_per_sample": grid.steps_per_sample,
            "sample_interval_s": grid.sample_interval_s,
            "n_steps": grid.n_steps,
            "shortest_contact_time_s": shortest_contact_time_s(setup),
        },
        "peak_force_n": peaks,
        "peak_time_s": peak_times,
        "max_force_over_yield": float(np.max(np.asarray(traces.max_force_n) / np.asarray(traces.yield_force_n))),
        "energy_balance": {
            "initial_energy_j": energy0,
            "final_kinetic_j": float(traces.kinetic_j[-1]),
            "final_potential_j": float(traces.potential_j[-1]),
            "dissipated_viscous_j": float(traces.dissipated_viscous_j[-1]),
            "dissipated_friction_j": float(traces.dissipated_friction_j[-1]),
            "dissipated_plastic_j": float(traces.dissipated_plastic_j[-1]),
            "max_relative_error": float(np.max(np.abs(np.asarray(traces.energy_error_j))) / energy0),
        },
        "momentum_balance": {
            "initial_momentum_kg_m_s": float(traces.initial_momentum_kg_m_s),
            "final_momentum_kg_m_s": float(traces.momentum_kg_m_s[-1]),
            "wall_impulse_n_s": float(traces.wall_impulse_n_s[-1]),
            "friction_impulse_n_s": float(traces.friction_impulse_n_s[-1]),
            "preload_impulse_n_s": float(traces.preload_impulse_n_s[-1]),
            "max_abs_error_kg_m_s": float(np.max(momentum_error)),
        },
    }
