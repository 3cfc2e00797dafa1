"""Runtime of a sensitivity sweep of 1000 setups and of one experiment-design optimisation.

Run: `python benchmarks/sensitivity_bench.py [--setups 1000] [--small] [--out FILE]`.

1. `hertzchain.sensitivity.sensitivity_sweep` on the paper's chain (21 beads, 2 ms record,
   1 us sampling): 4 parameters (eta, mu, wall_youngs, striker_velocity) x 4 observables
   (wall_peak, contact_10_peak, force_ratio_10, contact_10_arrival), forward mode, over an
   impact-velocity x wall-modulus grid of `--setups` points (40 x 25 by default), vmapped in
   chunks of 100. Compile time (first chunk of the same shape) and run time are separate.
2. `fitting.design.optimize_plan` for eta, mu, C of the paper's chain: 6 candidate
   velocities x 7 candidate channels, a plan of 4 recordings (D-optimal), 1 us sampling,
   2.5 ms records; total wall time (simulating the candidates, the Jacobian by forward mode
   and the search), and the time of the search alone.

Prints the numbers and writes them as JSON (default `benchmarks/results/sensitivity_bench/latest.json`).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import jax
import numpy as np

import hertzchain as hc
from hertzchain import sensitivity as S
from hertzchain.io.atomic import write_json


def sweep_benchmark(n_setups: int, chunk_size: int) -> dict:
    n_v = max(2, int(round(np.sqrt(n_setups * 40 / 25))))
    n_w = max(1, int(round(n_setups / n_v)))
    velocities = np.geomspace(0.05, 1.0, n_v)
    walls = np.geomspace(3e9, 4e11, n_w)
    setup = hc.ChainSetup(eta_s=1.7e-6, mu=0.12, mu_star=0.03)
    params = ("eta_s", "mu", "wall_youngs_pa", "striker_velocity_m_s")
    observables = ("wall_peak", "contact_10_peak", "force_ratio_10", "contact_10_arrival")
    kwargs = dict(t_end_s=2.0e-3, sample_interval_s=1e-6, chunk_size=chunk_size, progress=False)
    # compile on one chunk of the same shape (the same grid step as the full sweep)
    start = time.perf_counter()
    # (at least one full chunk, with the most demanding corner so that the time step is
    # the sweep's own)
    warm_walls = [walls[0], walls[-1]]
    warm_velocities = velocities[: max(1, -(-chunk_size // 2))]
    warm_velocities = np.unique(np.concatenate([warm_velocities, velocities[-1:]]))
    S.sensitivity_sweep(setup, params, observables,
                        {"striker_velocity_m_s": warm_velocities, "wall_youngs_pa": warm_walls}, **kwargs)
    warm = time.perf_counter() - start
    start = time.perf_counter()
    result = S.sensitivity_sweep(setup, params, observables,
                                 {"striker_velocity_m_s": velocities, "wall_youngs_pa": walls}, **kwargs)
    elapsed = time.perf_counter() - start
    n = int(np.prod(result.grid_shape))
    valid = {o: int(result.valid[o].sum()) for o in observables}
    return {
        "setups": n,
        "grid": [int(n_v), int(n_w)],
        "params": list(params),
        "observables": list(observables),
        "mode": result.mode,
        "dt_s": result.time_grid.dt_s,
        "steps_per_run": result.time_grid.n_steps,
        "chunk_size": chunk_size,
        "first_call_s (compile + 1 chunk)": warm,
        "sweep_s": elapsed,
        "setups_per_s": n / elapsed,
        "valid_points": valid,
    }


def design_benchmark(small: bool) -> dict:
    from fitting import design as fd

    setup = hc.ChainSetup(eta_s=1.7e-6, mu=0.12, mu_star=0.03)
    values = {"eta_s": 1.7e-6, "mu": 0.12, "mu_star": 0.03}
    velocities = [0.1, 0.4] if small else [0.03, 0.06, 0.1, 0.2, 0.4, 0.8]
    channels = ["contact_6", "wall"] if small else [
        "contact_2", "contact_6", "contact_10", "contact_14", "contact_18", "contact_20", "wall"]
    start = time.perf_counter()
    opt = fd.optimize_plan(
        setup, ("eta_s", "mu", "C"), candidate_velocities_m_s=velocities, candidate_channels=channels,
        size=2 if small else 4, values=values, noise_std_n=0.5, sample_interval_s=1e-6,
        t_end_s=1.6e-3 if small else 2.5e-3, baseline_units=[(0.3, "contact_6"), (0.3, "wall")],
        progress=False,
    )
    total = time.perf_counter() - start
    n_units = len(opt.candidates["velocities_m_s"]) * len(opt.candidates["channels"])
    start = time.perf_counter()
    for _ in range(3):
        for v, c in [(v, c) for v in opt.candidates["velocities_m_s"] for c in opt.candidates["channels"]]:
            try:
                opt.evaluate([(v, c)] + opt.chosen[1:])
            except fd.DesignError:
                pass
    evaluation = (time.perf_counter() - start) / (3 * n_units)
    return {
        "candidates": n_units,
        "plan_size": opt.size,
        "chosen": [[v, c] for v, c in opt.chosen],
        "total_s (simulate candidates + Jacobian + search)": total,
        "one_plan_evaluation_s": evaluation,
        "relative_stderr_recommended": opt.recommended.relative_stderr,
        "relative_stderr_baseline": opt.baseline.relative_stderr,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--setups", type=int, default=1000, help="setups in the sweep [1000]")
    parser.add_argument("--chunk-size", type=int, default=100, help="setups per vmapped call [100]")
    parser.add_argument("--small", action="store_true", help="a quick run (64 setups, small design)")
    parser.add_argument("--skip-design", action="store_true")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "sensitivity_bench" / "latest.json"))
    args = parser.parse_args()
    n_setups = 64 if args.small else args.setups
    chunk = min(args.chunk_size, 32) if args.small else args.chunk_size
    results = {
        "device": str(jax.devices()[0]),
        "platform": platform.platform(),
        "sweep": sweep_benchmark(n_setups, chunk),
    }
    print(json.dumps(results["sweep"], indent=2))
    if not args.skip_design:
        results["design"] = design_benchmark(args.small)
        print(json.dumps(results["design"], indent=2))
    write_json(args.out, results)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
