"""The diagnosis on records made by a second code path, not the kernel it fits with.

Two cases on the brass chain of `benchmarks/independent_data.py` (15 beads of 5 mm struck by
a 3 mm brass ball; contacts 5 and 10 and the wall recorded; five shots 0.05-1.5 m/s; 0.5 %
noise, an 11-bit converter, 2 us sampling, piezo channels; the header states the nominal
chain, its wall brass at 110 GPa):

- `wall`: a 20 GPa wall, simulated by the diffrax reference solver (`hertzchain.reference`);
  it must be named `wall_compliance`, with the wall's modulus in GPa.
- `plasticity`: contacts that yield by Thornton's law (1997: Hertz to the yield overlap,
  then linear loading at the tangent stiffness of yield, Hertzian unloading with an enlarged
  radius about a residual overlap), integrated here by a NumPy velocity Verlet at 10 ns
  steps; the diagnosis's candidate is Jackson & Green's law, so the effect, not its law, is
  what is missing; it must be named `plasticity`. The yield force of a bead-bead contact is
  0.6 of the largest force such a contact reaches elastically (`independent_data`'s
  strength). With an infinite yield force the NumPy generator is checked against the diffrax
  reference on the elastic chain (`elastic_check`).

    python benchmarks/diagnosis_second_path.py [--cases wall,plasticity] [--out DIR]

Writes `DIR/latest.json` (default `benchmarks/results/diagnosis_second_path`): per case the
effects named, the alarm, the convergence, the wall modulus or yield stress read, the run time
(`runtime_s`, the diagnosis from the records made), with the machine's load average.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import hertzchain as hc  # noqa: E402
from fitting.diagnosis import diagnose  # noqa: E402
from hertzchain.acquisition import Acquisition, acquire  # noqa: E402
from hertzchain.atomic import json_ready, write_json  # noqa: E402
from hertzchain.chain import build_model  # noqa: E402
from hertzchain.reference import simulate_reference  # noqa: E402
from hertzchain.tracefile import TraceFile, setup_header  # noqa: E402
from independent_data import SETUPS, hidden_records, true_strength  # noqa: E402

SETUP = "brass"
WALL_YOUNGS_PA = 20e9
VERLET_STEP_S = 10e-9
RECORD_EVERY = 25  # fine samples of 0.25 us, as `independent_data`


def _thornton(overlap, max_overlap, kappa, yield_force):
    """Thornton's (1997) contact force, N, at `overlap` after the largest overlap `max_overlap`
    (m); `kappa` the Hertz stiffness (N/m^1.5), `yield_force` N (inf: Hertz)."""
    yield_overlap = (yield_force / kappa) ** (2 / 3)
    tangent = 1.5 * kappa * np.sqrt(yield_overlap)
    plastic = max_overlap > yield_overlap
    peak = np.where(plastic, yield_force + tangent * (max_overlap - yield_overlap), kappa * max_overlap ** 1.5)
    peak_plastic = np.where(plastic, peak, yield_force)  # only read where plastic
    radius_ratio = ((2 * peak_plastic + yield_force) / 3) ** 1.5 / (peak_plastic * np.sqrt(yield_force))
    kappa_unload = kappa * np.sqrt(np.where(plastic, radius_ratio, 1.0))
    residual = np.where(plastic, max_overlap - (peak / kappa_unload) ** (2 / 3), 0.0)
    loading = np.where(plastic, yield_force + tangent * (overlap - yield_overlap), kappa * np.maximum(overlap, 0) ** 1.5)
    unloading = kappa_unload * np.maximum(overlap - residual, 0.0) ** 1.5
    return np.where(overlap >= max_overlap, loading, unloading) * (overlap > 0)


def thornton_chain(setups, t_end_s: float, contacts, yield_forces_n=None):
    """Velocity Verlet (step `VERLET_STEP_S`) of the chains `setups` (one per shot, same chain,
    no dissipation, no preload) with Thornton contacts whose yield forces are `yield_forces_n`
    (striker-bead, bead-bead..., wall; None: Hertz). Returns (time s, {channel: (shots, samples)}
    forces N) sampled every `RECORD_EVERY` steps."""
    model = build_model(setups[0])
    mass = np.asarray(model.mass_kg)
    kappa = np.append(np.asarray(model.kappa), float(model.wall_kappa))
    forces_y = np.full(kappa.size, np.inf) if yield_forces_n is None else np.asarray(yield_forces_n, dtype=float)
    forces_y = np.where(np.isfinite(forces_y), forces_y, 1e30)
    shots = len(setups)
    u = np.zeros((shots, mass.size))
    v = np.zeros_like(u)
    v[:, 0] = [float(s.striker_velocity_m_s) for s in setups]
    max_overlap = np.zeros((shots, kappa.size))
    dt = VERLET_STEP_S
    n_samples = int(round(t_end_s / (dt * RECORD_EVERY)))
    wanted = list(contacts) + [kappa.size - 1]
    record = np.zeros((n_samples, shots, len(wanted)))

    def contact_forces(u):
        overlap = np.concatenate([u[:, :-1] - u[:, 1:], u[:, -1:]], axis=1)
        np.maximum(max_overlap, overlap, out=max_overlap)
        return _thornton(overlap, max_overlap, kappa, forces_y)

    def accel(f):
        net = -f.copy()  # each contact pushes the body before it back ...
        net[:, 1:] += f[:, :-1]  # ... and the one after it forward (the wall takes the last)
        return net / mass

    f = contact_forces(u)
    a = accel(f)
    for k in range(n_samples):
        for _ in range(RECORD_EVERY):
            v += 0.5 * dt * a
            u += dt * v
            f = contact_forces(u)
            a = accel(f)
            v += 0.5 * dt * a
        record[k] = f[:, wanted]
    time_s = dt * RECORD_EVERY * np.arange(1, n_samples + 1)
    names = [f"contact_{c}" for c in contacts] + ["wall"]
    return time_s, {name: record[:, :, i].T for i, name in enumerate(names)}


def _records(runs, spec, label, seed):
    """`TraceFile`s of the brass chain's shots from (time, {channel: force}) runs, acquired as
    `independent_data.hidden_records` does; the header is the nominal chain."""
    files = []
    for k, (velocity, (time_s, forces)) in enumerate(zip(spec["velocities_m_s"], runs)):
        nominal = hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=velocity, **spec["fields"])
        noise = {n: 0.005 * float(np.max(f)) for n, f in forces.items()}
        record = acquire(time_s, forces, Acquisition(sample_interval_s=2e-6, noise_std_n=noise, bits=11,
                                                     coupling="ac"), seed=1000 * seed + k, static_n=0.0)
        header = setup_header(nominal)
        header["noise_std_n"] = max(record.noise_std_n.values())
        for name in record.channels:
            header[f"noise_std_n_{name}"] = record.noise_std_n[name]
        header["x_hidden_effects"] = label
        header["x_code_path"] = "numpy_thornton_verlet"
        files.append(TraceFile(header, record.time_s, record.channels, path=f"{SETUP}_{velocity:g}"))
    return files


def thornton_records(seed: int = 0):
    """The plasticity case's records and the true yield forces (N) of its contacts."""
    spec = SETUPS[SETUP]
    target = true_strength(SETUP, "plasticity")  # a bead-bead contact's yield force, N
    probe = hc.ChainSetup(spec["n_beads"], plasticity=True, plastic_law="thornton", **spec["fields"])
    forces_y = np.asarray(probe.contact_yield_force_n(), dtype=float)
    forces_y = forces_y * target / forces_y[1]  # F_Y ~ sigma_Y^3: one stress for every contact
    setups = [hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=v, **spec["fields"])
              for v in spec["velocities_m_s"]]
    time_s, forces = thornton_chain(setups, spec["record_s"], spec["contacts"], forces_y)
    runs = [(time_s, {n: f[k] for n, f in forces.items()}) for k in range(len(setups))]
    return _records(runs, spec, "plasticity (Thornton)", seed), forces_y


def elastic_check() -> float:
    """Largest difference of the NumPy generator without yield from the diffrax reference on
    the fastest shot, over the largest force of each channel."""
    spec = SETUPS[SETUP]
    setup = hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=max(spec["velocities_m_s"]), **spec["fields"])
    time_s, forces = thornton_chain([setup], spec["record_s"], spec["contacts"])
    reference = simulate_reference(setup, t_end_s=spec["record_s"], sample_interval_s=0.25e-6,
                                   contacts=spec["contacts"], rtol=1e-9)
    worst = 0.0
    for name, values in forces.items():
        other = np.asarray(reference.forces_n[name])
        n = min(other.size, values.shape[1])
        worst = max(worst, float(np.max(np.abs(values[0, :n] - other[:n])) / np.max(np.abs(other))))
    return worst


def _summary(diagnosis, began: float) -> dict:
    out = {
        "named": list(diagnosis.missing_effects), "alarm": bool(diagnosis.misspecification),
        "converged": bool(diagnosis.converged), "unconverged_fits": list(diagnosis.unconverged),
        "gap_base": diagnosis.base_fit["gap"], "gap_final": diagnosis.final["gap"],
        "runtime_s": time.perf_counter() - began, "diagnosis_s": diagnosis.elapsed_s,
        "conclusion": diagnosis.conclusion,
        "refitted": [[c.effect for c in step.candidates if c.converged is not None] for step in diagnosis.steps],
    }
    final, errors = diagnosis.final["values"], diagnosis.final["stderr"]
    if "wall_softening" in final:
        header = float(diagnosis.problem.base_setups[0].wall_youngs_pa)
        wall = header * math.exp(-final["wall_softening"])
        out["wall_youngs_gpa"] = {"fitted": wall / 1e9, "stderr": wall * errors["wall_softening"] / 1e9,
                                  "true": WALL_YOUNGS_PA / 1e9, "header": header / 1e9}
    if "yield_softening" in final:
        out["yield_softening"] = {"fitted": final["yield_softening"], "stderr": errors["yield_softening"]}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="wall,plasticity")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results/diagnosis_second_path"))
    args = parser.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    results = {"setup": {SETUP: {k: v for k, v in SETUPS[SETUP].items() if k != "fields"}},
               "cpu_count": os.cpu_count(), "load_average_1min_at_start": os.getloadavg()[0],
               "data": "0.5 % noise, 11 bits, 2 us, piezo channels, true header velocity, nominal header", "cases": {}}
    for case in cases:
        began = time.perf_counter()
        if case == "wall":
            files = hidden_records(SETUP, ("wall_compliance",), code_path="diffrax")
            made = time.perf_counter()
            entry = {"code_path": "diffrax (hertzchain.reference)", "expected": ["wall_compliance"]}
        elif case == "plasticity":
            results["elastic_check_max_relative_difference"] = elastic_check()
            began = time.perf_counter()
            files, forces_y = thornton_records()
            made = time.perf_counter()
            entry = {"code_path": "NumPy velocity Verlet, Thornton contacts, 10 ns", "expected": ["plasticity"],
                     "true_yield_force_bead_bead_n": float(forces_y[1])}
        else:
            raise SystemExit(f"--cases: unknown case {case!r} (wall, plasticity)")
        entry["data_s"] = made - began
        diagnosis = diagnose(files, progress=True)
        entry.update(_summary(diagnosis, made))
        entry["correct"] = entry["named"] == entry["expected"]
        results["cases"][case] = entry
        print(f"{case}: named {entry['named']} (alarm {entry['alarm']}, converged {entry['converged']}) "
              f"in {entry['runtime_s']:.0f} s", flush=True)
    results["load_average_1min_at_end"] = os.getloadavg()[0]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "latest.json", json_ready(results))
    return 0 if all(e["correct"] for e in results["cases"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
