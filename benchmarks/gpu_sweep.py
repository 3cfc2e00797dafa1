"""Bead-steps per second of large sweeps (10^4 to 10^6 chains) on an accelerator.

    python benchmarks/gpu_sweep.py --out gpu_sweep.json [--sizes 10000,100000,1000000]

Runs `hertzchain.batched.solve_batched` on the paper's chain (N = 21, dissipationless,
dt = 1 us, 2500 steps, three forces recorded every 10 us, the largest force of every contact
tracked every step), over impact velocities 0.1..1 m/s and wall moduli 3..400 GPa, on every
local device of the default backend (a GPU if JAX sees one, else the CPU with smaller
default sizes). Chains are run in chunks of at most `--chunk` per device call. Needs only
JAX and hertzchain (no Numba). Writes JSON: device, sizes, wall times, bead-steps/s,
compile time, and a physics check (largest wall force against the single-chain solver).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="output JSON file")
    parser.add_argument("--sizes", help="comma-separated chain counts [GPU: 1e4,1e5,1e6; CPU: 1e3,1e4]")
    parser.add_argument("--chunk", type=int, default=262144, help="chains per device call [262144]")
    parser.add_argument("--n-beads", type=int, default=21)
    parser.add_argument("--steps", type=int, default=2500)
    parser.add_argument("--block-steps", type=int, default=None, help="steps unrolled per loop iteration")
    args = parser.parse_args(argv)

    import jax
    import numpy as np

    import hertzchain as hc
    from hertzchain.atomic import write_json
    from hertzchain.batched import DEFAULT_BLOCK_STEPS, solve_batched
    from hertzchain.integrate import Recording

    devices = jax.devices()
    platform = devices[0].platform
    if args.sizes:
        sizes = [int(float(s)) for s in args.sizes.split(",")]
    else:
        sizes = [10_000, 100_000, 1_000_000] if platform != "cpu" else [1_000, 10_000]
    block = args.block_steps or DEFAULT_BLOCK_STEPS
    n = args.n_beads
    dt = 1e-6
    recording = Recording((n // 2 - 1, n // 2))
    results = []
    for size in sizes:
        side = int(math.sqrt(size))
        chunk = min(args.chunk, size)
        velocities = np.geomspace(0.1, 1.0, side)
        walls = np.geomspace(3e9, 400e9, math.ceil(size / side))
        setup_all, _ = hc.batch_setup(hc.ChainSetup(n), striker_velocity_m_s=velocities, wall_youngs_pa=walls)
        setup_all = jax.tree_util.tree_map(lambda leaf: leaf[:size], setup_all)
        grid = hc.choose_time_grid(
            setup_all, t_end_s=args.steps * dt, sample_interval_s=10 * dt, dt_s=dt
        )

        def run_all():
            peaks = []
            for start in range(0, size, chunk):
                part = jax.tree_util.tree_map(lambda leaf: leaf[start : start + chunk], setup_all)
                out = solve_batched(part, grid, recording, block_steps=block,
                                    devices=devices if len(devices) > 1 else None, pad_to=chunk)
                peaks.append(np.asarray(out.max_force_n[:, -1]))
            return np.concatenate(peaks)

        start = time.perf_counter()
        peaks = run_all()
        first = time.perf_counter() - start
        start = time.perf_counter()
        peaks = run_all()
        elapsed = time.perf_counter() - start
        single = hc.simulate(
            jax.tree_util.tree_map(lambda leaf: leaf[size - 1], setup_all),
            t_end_s=args.steps * dt, sample_interval_s=10 * dt, dt_s=dt, on_yield="ignore",
        )
        check = abs(float(single.max_force_n[-1]) - float(peaks[-1])) / float(single.max_force_n[-1])
        row = {
            "chains": size,
            "chunk": chunk,
            "first_call_s": first,
            "run_s": elapsed,
            "compile_s": max(first - elapsed, 0.0),
            "bead_steps_per_s": n * size * args.steps / elapsed,
            "wall_peak_relative_difference_to_simulate": check,
        }
        print(json.dumps(row), flush=True)
        results.append(row)
    write_json(args.out, {
        "device": str(devices[0].device_kind),
        "platform": platform,
        "n_devices": len(devices),
        "jax": jax.__version__,
        "n_beads": n,
        "steps": args.steps,
        "dt_s": dt,
        "block_steps": block,
        "results": results,
    })
    return 0


if __name__ == "__main__":
    sys.exit(main())
