"""Power-law contacts on the full C++ kernel (its power-law library) against the JAX kernel.

1. A sweep's call: the standard damped + frictional case of `run.py` (N = 21, B = 1024, 2500
   steps of 1 us, eta = 2 us, mu = 0.19) with every contact on the power law n = 1.6,
   `solve_batched` with the books, the default kernel and `kernel="jax"`, interleaved
   (medians of `--repeats` runs after a first, compiling one).
2. A fit's evaluation: the forces of 10 such chains (impact speeds 0.15-0.6 m/s, contacts 9,
   10 and the wall) and their Jacobian in eta, mu and the exponent n, `jax.jacfwd` through
   `record_batched` (one kernel run with its tangents on the C++ kernel), both kernels.

    python benchmarks/power_law_kernel.py --out benchmarks/results/power_law_kernel
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
EXPONENT = 1.6


def _timed(calls: dict, repeats: int) -> dict:
    import jax

    for call in calls.values():  # compile
        jax.block_until_ready(call())
    times = {name: [] for name in calls}
    for _ in range(repeats):
        for name, call in calls.items():
            start = time.perf_counter()
            jax.block_until_ready(call())
            times[name].append(time.perf_counter() - start)
    return {"median_s": {name: statistics.median(t) for name, t in times.items()}, "runs_s": times}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    import equinox as eqx
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    sys.path.insert(0, str(HERE))
    from run import DAMPED_ETA_S, DAMPED_MU, DT_S

    import hertzchain as hc
    from hertzchain import native
    from hertzchain.batched import kernel_flags, record_batched, solve_batched

    start = time.perf_counter()
    reason = native.unavailable_reason()
    native._load_power()  # both libraries built once, outside every timing
    build_s = time.perf_counter() - start

    side = 32
    base = hc.ChainSetup(21, eta_s=DAMPED_ETA_S, mu=DAMPED_MU, contact_exponent=EXPONENT)
    setup, _ = hc.batch_setup(base, striker_velocity_m_s=np.geomspace(0.1, 1.0, side),
                              wall_youngs_pa=np.geomspace(3e9, 400e9, side))
    grid = hc.choose_time_grid(setup, t_end_s=2500 * DT_S, sample_interval_s=DT_S, dt_s=DT_S)
    recording = hc.Recording((9, 10))
    sweep = _timed({"fused": lambda: solve_batched(setup, grid, recording),
                    "jax": lambda: solve_batched(setup, grid, recording, kernel="jax")}, args.repeats)
    fused, jaxk = (solve_batched(setup, grid, recording, kernel=k) for k in ("auto", "jax"))
    energy = np.asarray(jaxk.initial_energy_j).max()
    sweep["speedup_fused_over_jax"] = sweep["median_s"]["jax"] / sweep["median_s"]["fused"]
    sweep["throughput_bead_steps_per_s"] = {k: 21 * 1024 * grid.n_steps / t for k, t in sweep["median_s"].items()}
    sweep["dissipated_difference_over_impact_energy"] = float(
        np.max(np.abs(np.asarray(fused.dissipated_j) - np.asarray(jaxk.dissipated_j))) / energy)
    sweep["force_difference_over_peak"] = max(
        float(np.max(np.abs(np.asarray(fused.forces_n[k]) - np.asarray(jaxk.forces_n[k]))
                     / np.max(np.abs(np.asarray(jaxk.forces_n[k]))))) for k in fused.forces_n)

    chains, _ = hc.batch_setup(base, striker_velocity_m_s=np.linspace(0.15, 0.6, 10))
    fit_grid = hc.choose_time_grid(chains, t_end_s=2.5e-3, sample_interval_s=1e-6)
    flags = kernel_flags(chains)._replace(ledger=False)
    fit_recording = hc.Recording((9, 10))
    ones = jnp.ones(10)

    def forces(q, kernel):
        setup_q = eqx.tree_at(lambda s: (s.eta_s, s.mu, s.contact_exponent), chains,
                              (q[0] * ones, q[1] * ones, q[2] * ones))
        out = record_batched(setup_q, fit_grid, fit_recording, flags, kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([DAMPED_ETA_S, DAMPED_MU, EXPONENT])
    evaluations = {kernel: jax.jit(lambda q, k=kernel: (forces(q, k), jax.jacfwd(lambda q: forces(q, k))(q)))
                   for kernel in ("auto", "jax")}
    fit = _timed({"fused": lambda: evaluations["auto"](q), "jax": lambda: evaluations["jax"](q)}, args.repeats)
    (forces_fused, j_fused), (forces_jax, j_jax) = evaluations["auto"](q), evaluations["jax"](q)
    fit["force_difference_over_peak"] = float(np.max(np.abs(np.asarray(forces_fused) - np.asarray(forces_jax)))
                                              / np.max(np.abs(np.asarray(forces_jax))))
    fit["speedup_fused_over_jax"] = fit["median_s"]["jax"] / fit["median_s"]["fused"]
    fit["jacobian_difference_over_column_peak"] = [
        float(np.max(np.abs(np.asarray(j_fused[..., i]) - np.asarray(j_jax[..., i])))
              / np.max(np.abs(np.asarray(j_jax[..., i])))) for i in range(3)]
    fit["steps"] = fit_grid.n_steps

    result = {
        "machine": {"cores": len(os.sched_getaffinity(0)), "load_before": os.getloadavg()},
        "native": reason or "available",
        "libraries_load_or_build_s": build_s,
        "exponent": EXPONENT,
        "sweep_with_books": sweep | {"case": "N = 21, B = 1024, 2500 steps of 1 us, eta = 2 us, mu = 0.19, n = 1.6"},
        "fit_evaluation": fit | {"case": "forces and Jacobian in eta, mu, n; 10 chains, contacts 9, 10, wall"},
    }
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "power_law_kernel.json"
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps(result, indent=2))
    os.replace(partial, path)
    print(json.dumps({"sweep": sweep["median_s"], "fit": fit["median_s"],
                      "jacobian_difference": fit["jacobian_difference_over_column_peak"]}, indent=1))


if __name__ == "__main__":
    main()
