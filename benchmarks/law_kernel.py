"""Contact laws other than Hertz's on the full C++ kernel (each law's library) against the JAX kernel.

`--law power_law`: every contact on the power law n = 1.6; `--law thornton` or
`--law jackson_green`: the elastic-plastic laws at the paper's sigma_Y = 2 GPa (the faster
strikers yield the contacts).

1. A sweep's call: the standard damped + frictional case of `run.py` (N = 21, B = 1024, 2500
   steps of 1 us, eta = 2 us, mu = 0.19) with every contact on the law, `solve_batched` with
   the books, the default kernel and `kernel="jax"`, interleaved (medians of `--repeats` runs
   after a first, compiling one); the elastic-plastic laws also undamped, without friction,
   where the JAX kernel is also timed in the full step's state (`KernelFlags.full_step`, the
   state the C++ kernel's undamped runs use; not kept for the JAX kernel).
   Impact speeds 0.1-1 m/s (power law) or 0.5-5 m/s (elastic-plastic: most of them yield).
2. A fit's evaluation: the forces of 10 such chains (impact speeds 0.15-0.6 m/s, or 1.5-6 m/s
   for the elastic-plastic laws; contacts 9, 10 and the wall) and their Jacobian in eta, mu
   and the law's constant (the exponent n, or the yield stress), `jax.jacfwd` through
   `record_batched` (one kernel run with its tangents on the C++ kernel), both kernels.

    python benchmarks/law_kernel.py --law power_law --out benchmarks/results/law_kernel
    python benchmarks/law_kernel.py --law jackson_green --out benchmarks/results/law_kernel
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
YIELD_STRESS_PA = 2e9  # the paper's beads
# each law's `ChainSetup` fields, its constant the fit frees, its value, and the impact speeds
# (m/s) of the sweep and of the fit
LAWS = {
    "power_law": ({"contact_exponent": EXPONENT}, "contact_exponent", EXPONENT, (0.1, 1.0), (0.15, 0.6)),
    "thornton": ({"plasticity": True, "bead_yield_stress_pa": YIELD_STRESS_PA}, "bead_yield_stress_pa",
                 YIELD_STRESS_PA, (0.5, 5.0), (1.5, 6.0)),
    "jackson_green": ({"plasticity": True, "plastic_law": "jackson_green", "bead_yield_stress_pa": YIELD_STRESS_PA},
                      "bead_yield_stress_pa", YIELD_STRESS_PA, (0.5, 5.0), (1.5, 6.0)),
}


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
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--law", choices=list(LAWS), required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    import equinox as eqx
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    sys.path.insert(0, str(HERE))
    from run_workers import DAMPED_ETA_S, DAMPED_MU, DT_S

    import hertzchain as hc
    from hertzchain import batched, native
    from hertzchain.batched import kernel_flags, record_batched, solve_batched

    start = time.perf_counter()
    reason = native.unavailable_reason()
    native._load_named(args.law)  # both libraries built once, outside every timing
    build_s = time.perf_counter() - start
    fields, constant, value, sweep_speeds, fit_speeds = LAWS[args.law]

    def jax_in_full_state(setup, grid, recording):
        """`solve_batched(kernel="jax")` with the full step's state (`KernelFlags.full_step`)."""
        flags = batched.kernel_flags(setup)._replace(full_step=True)
        names, rows, user = batched._plan(setup, recording)
        params = batched.share_uniform(batched.kernel_params(setup))
        return batched._solve_fast(params, batched.batch_size(setup), flags, grid, rows, names, user,
                                   batched.DEFAULT_BLOCK_STEPS, None, None)

    def timed_sweep(base, full_state_too: bool = False) -> dict:
        side = 32
        setup, _ = hc.batch_setup(base, striker_velocity_m_s=np.geomspace(*sweep_speeds, side),
                                  wall_youngs_pa=np.geomspace(3e9, 400e9, side))
        grid = hc.choose_time_grid(setup, t_end_s=2500 * DT_S, sample_interval_s=DT_S, dt_s=DT_S)
        recording = hc.Recording((9, 10))
        calls = {"fused": lambda: solve_batched(setup, grid, recording),
                 "jax": lambda: solve_batched(setup, grid, recording, kernel="jax")}
        if full_state_too:
            calls["jax_full_state"] = lambda: jax_in_full_state(setup, grid, recording)
        sweep = _timed(calls, args.repeats)
        fused, jaxk = (solve_batched(setup, grid, recording, kernel=k) for k in ("auto", "jax"))
        energy = np.asarray(jaxk.initial_energy_j)
        sweep["speedup_fused_over_jax"] = sweep["median_s"]["jax"] / sweep["median_s"]["fused"]
        sweep["throughput_bead_steps_per_s"] = {k: 21 * 1024 * grid.n_steps / t for k, t in sweep["median_s"].items()}
        sweep["dissipated_difference_over_impact_energy"] = float(
            np.max(np.abs(np.asarray(fused.dissipated_j) - np.asarray(jaxk.dissipated_j))) / energy.max())
        sweep["dissipated_fraction_median"] = float(np.median(np.asarray(jaxk.dissipated_j) / energy))
        sweep["largest_force_difference_relative"] = float(
            np.max(np.abs(np.asarray(fused.max_force_n) / np.asarray(jaxk.max_force_n) - 1.0)))
        sweep["force_difference_over_peak"] = max(
            float(np.max(np.abs(np.asarray(fused.forces_n[k]) - np.asarray(jaxk.forces_n[k]))
                         / np.max(np.abs(np.asarray(jaxk.forces_n[k]))))) for k in fused.forces_n)
        return sweep

    base = hc.ChainSetup(21, eta_s=DAMPED_ETA_S, mu=DAMPED_MU, **fields)
    sweep = timed_sweep(base)
    undamped = timed_sweep(hc.ChainSetup(21, **fields), full_state_too=True) if "plasticity" in fields else None

    chains, _ = hc.batch_setup(base, striker_velocity_m_s=np.linspace(*fit_speeds, 10))
    fit_grid = hc.choose_time_grid(chains, t_end_s=2.5e-3, sample_interval_s=1e-6)
    flags = kernel_flags(chains)._replace(ledger=False)
    fit_recording = hc.Recording((9, 10))
    ones = jnp.ones(10)

    def forces(q, kernel):
        setup_q = eqx.tree_at(lambda s: (s.eta_s, s.mu, getattr(s, constant)), chains,
                              (q[0] * ones, q[1] * ones, q[2] * ones))
        out = record_batched(setup_q, fit_grid, fit_recording, flags, kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([DAMPED_ETA_S, DAMPED_MU, value])
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
        "law": args.law, "setup": fields,
        "sweep_with_books": sweep | {"case": f"N = 21, B = 1024, 2500 steps of 1 us, eta = 2 us, mu = 0.19, "
                                             f"{args.law}, impact speeds {sweep_speeds} m/s"},
        "fit_evaluation": fit | {"case": f"forces and Jacobian in eta, mu, {constant}; 10 chains at "
                                         f"{fit_speeds} m/s, contacts 9, 10, wall"},
    } | ({"undamped_sweep_with_books": undamped | {"case": "the sweep without damping and friction"}}
         if undamped else {})
    path = args.out / args.law / "latest.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps(result, indent=2))
    os.replace(partial, path)
    print(json.dumps({"sweep": sweep["median_s"], "fit": fit["median_s"],
                      "undamped_sweep": undamped and undamped["median_s"],
                      "jacobian_difference": fit["jacobian_difference_over_column_peak"]}, indent=1))


if __name__ == "__main__":
    main()
