"""Sweeps of chains with other contact laws: the batched kernel against `solve` under `vmap`.

    python benchmarks/law_sweep.py [--out benchmarks/results/law_sweep] [--speeds 64]

The paper's chain (21 steel beads, steel wall) swept over striker speeds from 0.5 to 5 m/s
with, in turn, elastic-plastic contacts of measured contacts (`plastic_law="jackson_green"`,
sigma_Y = 2 GPa: the faster strikers yield), Thornton's elastic-plastic law, power-law
contacts (n = 1.7) and a linear dashpot (20 N s/m) with track friction (mu = 0.1). Each sweep
runs on `solve_batched` (the batched JAX kernel: these laws are not in the fused C++ kernels)
and on `solve_stacked` (`solve` under `vmap`, which sweeps of these laws ran before), each
timed cold (first call: tracing and compilation included) and warm (median of three further
calls), in one process, one after the other. The two must agree: largest difference of the
recorded forces relative to the largest force, and of the energy books relative to the
impact energy. Writes `latest.json` and `latest.md`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

T_END_S = 0.8e-3
SAMPLE_INTERVAL_S = 2e-6
LAWS = {
    "jackson_green": {"plasticity": True, "plastic_law": "jackson_green", "bead_yield_stress_pa": 2e9},
    "thornton": {"plasticity": True, "bead_yield_stress_pa": 2e9},
    "power_law_1.7": {"contact_exponent": 1.7},
    "dashpot_and_friction": {"dashpot_n_s_m": 20.0, "mu": 0.1},
}


def benchmark_law(name: str, speeds: int) -> dict:
    import jax

    import hertzchain as hc
    from hertzchain.batched import solve_batched
    from hertzchain.integrate import Recording, solve_stacked

    base = hc.ChainSetup(21, **LAWS[name])
    setup, _ = hc.batch_setup(base, striker_velocity_m_s=np.linspace(0.5, 5.0, speeds))
    grid = hc.choose_time_grid(setup, t_end_s=T_END_S, sample_interval_s=SAMPLE_INTERVAL_S)
    recording = Recording((5, 10, 15))

    def batched():
        return jax.block_until_ready(solve_batched(setup, grid, recording))

    def general():
        return jax.block_until_ready(solve_stacked(setup, grid, recording))

    from run_workers import _time  # (first call, median, min, max of the repeats, result)

    fast_cold, fast_warm, _, _, fast = _time(batched, 3)
    slow_cold, slow_warm, _, _, slow = _time(general, 3)
    scale = max(float(np.max(np.abs(slow.forces_n[c]))) for c in fast.channel_names)
    force_diff = max(float(np.max(np.abs(np.asarray(fast.forces_n[c]) - np.asarray(slow.forces_n[c]))))
                     for c in fast.channel_names)
    energy = np.asarray(slow.initial_energy_j)
    books_diff = float(np.max(np.abs(np.asarray(fast.dissipated_j) - np.asarray(slow.dissipated_j)[:, -1]) / energy))
    steps = grid.n_samples * grid.steps_per_sample
    return {
        "setup": LAWS[name], "chains": speeds, "steps": steps, "beads": 21,
        "batched_cold_s": fast_cold, "batched_warm_s": fast_warm,
        "vmap_solve_cold_s": slow_cold, "vmap_solve_warm_s": slow_warm,
        "speedup_warm": slow_warm / fast_warm, "speedup_cold": slow_cold / fast_cold,
        "batched_bead_steps_per_s": speeds * 22 * steps / fast_warm,
        "max_force_difference_relative": force_diff / scale,
        "max_dissipated_difference_relative": books_diff,
        "dissipated_fraction_fastest": float(np.asarray(fast.dissipated_j)[-1] / energy[-1]),
        "largest_energy_error_relative": float(np.max(np.abs(np.asarray(fast.energy_error_j)) / energy)),
    }


def markdown_table(result: dict) -> str:
    lines = [
        f"Sweeps of the paper's chain (21 beads) over {result['speeds']} striker speeds, 0.5-5 m/s, "
        f"{T_END_S * 1e3:.1f} ms; load average before {result['load_average_1min_before']:.2f}, "
        f"after {result['machine']['load_average_1min']:.2f} ({result['machine']['cpus']} CPUs).",
        "",
        "| law | batched kernel cold / warm (s) | `solve` under `vmap` cold / warm (s) | speed-up warm | "
        "forces differ by (of the largest) | dissipated energy differs by (of the impact energy) | "
        "dissipated at 5 m/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, row in result["laws"].items():
        lines.append(
            f"| {name} | {row['batched_cold_s']:.2f} / {row['batched_warm_s']:.3f} | "
            f"{row['vmap_solve_cold_s']:.2f} / {row['vmap_solve_warm_s']:.3f} | {row['speedup_warm']:.1f}x | "
            f"{row['max_force_difference_relative']:.1e} | {row['max_dissipated_difference_relative']:.1e} | "
            f"{100 * row['dissipated_fraction_fastest']:.1f} % |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import os

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "law_sweep"),
                        help="output folder [benchmarks/results/law_sweep]")
    parser.add_argument("--speeds", type=int, default=64, help="striker speeds per sweep [64]")
    args = parser.parse_args(argv)
    from fit_bench import machine_info

    from hertzchain.io.atomic import write_json, write_text

    load_before = os.getloadavg()[0]
    laws = {}
    for name in LAWS:
        print(f"{name} ...", file=sys.stderr, flush=True)
        laws[name] = benchmark_law(name, args.speeds)
    result = {"speeds": args.speeds, "load_average_1min_before": load_before, "laws": laws,
              "machine": machine_info()}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "latest.json", result)
    write_text(out / "latest.md", markdown_table(result))
    print(markdown_table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
