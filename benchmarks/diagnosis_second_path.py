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

    python benchmarks/diagnosis_second_path.py [--cases wall,plasticity] [--out DIR] [--profile]

Writes `DIR/latest.json` (default `benchmarks/results/diagnosis_second_path`): per case the
effects named, the alarm, the convergence, the wall modulus or yield stress read, the run time
(`runtime_s`, the diagnosis from the records made; `cpu_s`, its process CPU time; `loadavg`, the
1, 5 and 15 min load averages at its end), with the machine's load average. `--profile` writes
`DIR/profile.json` instead: per case where the diagnosis's seconds go (cProfile's cumulative
time of its stages and of the evaluator, JAX's compilations counted by event), nothing else.
"""

from __future__ import annotations

import argparse
import cProfile
import math
import os
import pstats
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax
from independent_data import SETUPS, hidden_records, true_strength

import hertzchain as hc
from fitting.diagnosis import diagnose
from hertzchain.acquisition import Acquisition, acquire
from hertzchain.chain import build_model
from hertzchain.io.atomic import json_ready, write_json
from hertzchain.io.tracefile import TraceFile, setup_header
from hertzchain.reference import simulate_reference

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
    n_samples = round(t_end_s / (dt * RECORD_EVERY))
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


def records(runs, spec, label, seed, code_path="numpy_thornton_verlet"):
    """`TraceFile`s of a chain's shots (`spec`: `n_beads`, `velocities_m_s`, `fields` as in
    `independent_data.SETUPS`) from (time s, {channel: force N}) runs, acquired as
    `independent_data.hidden_records` does (0.5 % noise, 11 bits, 2 us, piezo channels); the
    header is the nominal chain, with the hidden effects `label` and the `code_path` noted."""
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
        header["x_code_path"] = code_path
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
    return records(runs, spec, "plasticity (Thornton)", seed), forces_y


def elastic_check() -> float:
    """Largest difference of the NumPy generator without yield from the diffrax reference on
    the fastest shot, over the largest force of each channel."""
    spec = SETUPS[SETUP]
    setup = hc.ChainSetup(spec["n_beads"], striker_velocity_m_s=max(spec["velocities_m_s"]), **spec["fields"])
    _, forces = thornton_chain([setup], spec["record_s"], spec["contacts"])
    reference = simulate_reference(setup, t_end_s=spec["record_s"], sample_interval_s=0.25e-6,
                                   contacts=spec["contacts"], rtol=1e-9, on_yield="ignore")  # (elastic on purpose)
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


# The stages of a diagnosis and the evaluations under them, as (module path, function): the
# profile reports each one's cumulative time and calls (nested: a refit's time holds its fits').
PROFILED = (
    ("fitting/diagnosis/workflow.py", "base_fit"), ("fitting/diagnosis/workflow.py", "locate"),
    ("fitting/diagnosis/workflow.py", "screen"), ("fitting/diagnosis/workflow.py", "refit"),
    ("fitting/diagnosis/workflow.py", "heldout_check"), ("fitting/diagnosis/verdict.py", "name"),
    ("fitting/diagnosis/workflow.py", "backward_check"), ("fitting/diagnosis/report.py", "report"),
    ("fitting/diagnosis/screening.py", "screen"), ("fitting/diagnosis/refits.py", "refit"),
    ("fitting/diagnosis/refits.py", "fit"), ("fitting/diagnosis/refits.py", "stderr"),
    ("fitting/diagnosis/heldout.py", "heldout_chi2"), ("fitting/diagnosis/evaluator.py", "__call__"),
    ("fitting/diagnosis/evaluator.py", "residuals"), ("fitting/model.py", "__init__"),
)


def profiled_diagnosis(files) -> tuple:
    """`diagnose(files)` under cProfile timed by the process's CPU time (every thread's, the
    compiler's included; a load on the machine leaves it nearly unchanged, where it stretches
    wall times), with JAX's compile events summed: (diagnosis, breakdown): wall and CPU seconds,
    per stage of `PROFILED` its cumulative CPU seconds and calls, per JAX duration event
    (tracing, lowering, backend compilation) its count and wall seconds, the backend
    compilations also by compiled function, and the evaluator's counters (Jacobians, residual
    evaluations, their wall seconds). The native kernels' builds (a first run on a machine)
    run in child processes, outside the CPU time."""
    events = defaultdict(lambda: [0, 0.0])
    compiled = defaultdict(lambda: [0, 0.0])

    def listen(event, duration, fun_name=None, **_):
        events[event][0] += 1
        events[event][1] += duration
        if event.endswith("backend_compile_duration"):
            compiled[str(fun_name)][0] += 1
            compiled[str(fun_name)][1] += duration

    jax.monitoring.register_event_duration_secs_listener(listen)
    profiler = cProfile.Profile(timer=time.process_time)
    began, cpu = time.perf_counter(), time.process_time()
    try:
        diagnosis = profiler.runcall(diagnose, files, progress=True)
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    wall, cpu = time.perf_counter() - began, time.process_time() - cpu
    stats = pstats.Stats(profiler).stats
    stages = {}
    for path, function in PROFILED:
        hits = [(nc, ct) for (file, _, name), (_, nc, _, ct, _) in stats.items()
                if file.endswith(path) and name == function]
        if hits:
            stages[f"{path}:{function}"] = {"calls": sum(h[0] for h in hits), "cumulative_cpu_s": sum(h[1] for h in hits)}
    breakdown = {
        "wall_s": wall, "cpu_s": cpu, "loadavg": list(os.getloadavg()), "stages": stages,
        "jax_events": {name: {"count": n, "wall_s": t} for name, (n, t) in sorted(events.items())
                       if name.startswith("/jax/core/compile")},
        "backend_compilations": {name: {"count": n, "wall_s": t}
                                 for name, (n, t) in sorted(compiled.items(), key=lambda item: -item[1][1])},
        "evaluator": {"jacobians": diagnosis.evaluations, "residual_evaluations": diagnosis.residual_evaluations,
                      "wall_s": diagnosis.evaluation_seconds},
    }
    return diagnosis, breakdown


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="wall,plasticity")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results/diagnosis_second_path"))
    parser.add_argument("--profile", action="store_true", help="write DIR/profile.json: where the seconds go")
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
        cpu = time.process_time()
        if args.profile:
            diagnosis, entry["profile"] = profiled_diagnosis(files)
        else:
            diagnosis = diagnose(files, progress=True)
        entry.update(_summary(diagnosis, made))
        entry["cpu_s"] = time.process_time() - cpu  # every thread of the process; not the kernel builds
        entry["loadavg"] = list(os.getloadavg())
        entry["correct"] = entry["named"] == entry["expected"]
        results["cases"][case] = entry
        print(f"{case}: named {entry['named']} (alarm {entry['alarm']}, converged {entry['converged']}) "
              f"in {entry['runtime_s']:.0f} s", flush=True)
    results["load_average_1min_at_end"] = os.getloadavg()[0]
    results["conditions"] = (
        f"measured on {os.cpu_count()} cores, shared: 1-min load average {results['load_average_1min_at_start']:.1f} "
        f"at the start, {results['load_average_1min_at_end']:.1f} at the end (each case's `loadavg` at its end); "
        "wall times (`runtime_s`, `diagnosis_s`) are under that load, `cpu_s` is the process's CPU time")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / ("profile.json" if args.profile else "latest.json"), json_ready(results))
    return 0 if all(e["correct"] for e in results["cases"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
