"""Block-size tuning of the batched kernel on the standard case (N = 21, B = 1024, dt = 1 us).

    XLA_FLAGS=--xla_force_host_platform_device_count=2 python benchmarks/tune.py 5,10,20,40

Prints bead-steps/s for each number of steps unrolled per loop iteration, on all host devices.
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import jax  # noqa: E402
import numpy as np  # noqa: E402

import hertzchain as hc  # noqa: E402
from hertzchain.batched import solve_batched  # noqa: E402
from hertzchain.integrate import Recording  # noqa: E402


def main():
    blocks = [int(b) for b in (sys.argv[1] if len(sys.argv) > 1 else "5,10,20,40").split(",")]
    batch = int(sys.argv[2]) if len(sys.argv) > 2 else 1024
    side = 32 if batch == 1024 else 1
    setup, _ = hc.batch_setup(
        hc.ChainSetup(21),
        striker_velocity_m_s=np.geomspace(0.1, 1, side),
        wall_youngs_pa=np.geomspace(3e9, 4e11, batch // side),
    )
    grid = hc.choose_time_grid(setup, t_end_s=2.5e-3, sample_interval_s=1e-6, dt_s=1e-6)
    devices = jax.devices()
    for block in blocks:
        for use in ((devices[:1], devices) if batch > 1 else (devices[:1],)):
            run = lambda: jax.block_until_ready(  # noqa: E731
                solve_batched(setup, grid, Recording((9, 10)), block_steps=block,
                              devices=use if len(use) > 1 else None).forces_n
            )
            start = time.perf_counter()
            run()
            first = time.perf_counter() - start
            times = []
            for _ in range(5):
                start = time.perf_counter()
                run()
                times.append(time.perf_counter() - start)
            median = float(np.median(times))
            print(f"block {block:3d} devices {len(use)}: first {first:.2f} s, run {median * 1e3:.1f} ms, "
                  f"{21 * batch * 2500 / median:.3g} bead-steps/s", flush=True)


if __name__ == "__main__":
    main()
