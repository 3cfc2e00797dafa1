"""Time a full single-bead lock-in grid and its Jacobian (Lydon et al. 2015's grid).

    python benchmarks/driven_bench.py --out benchmarks/results/driven_bench.json [--label TEXT]
                                      [--frequencies 341] [--amplitudes 36] [--steps-per-period 64]

The grid: one 19.05 mm, 28 g steel bead between steel faces (Hertz sphere-flat), F0 = 0.133 N,
damping 1800 /s; 341 frequencies 3.0-4.7 kHz × 36 drive amplitudes 0.68-6.66 nm; ramp 25, hold
35, window 4 periods (60 periods a run). Times (median of `--repeats` after compilation): the
grid (`lockin_grid`, RMS and phase at f and f/2) and its Jacobian with respect to four
parameters (precompression, contact-stiffness scale, damping rate, drive scale) by
`jax.jacfwd`. The JSON records the machine (CPU count, load average) with the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import hertzchain  # noqa: F401  (float64)
from hertzchain.atomic import write_json
from hertzchain.driven import DrivenChain, lockin_grid


def timed(function, repeats: int) -> tuple[float, float]:
    """(first call incl. compilation, median of `repeats` later calls), s."""
    start = time.perf_counter()
    jax.block_until_ready(function())
    first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(function())
        times.append(time.perf_counter() - start)
    return first, statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="JSON file to write")
    parser.add_argument("--label", default="", help="what the machine was doing (e.g. 'loaded, shared 2 cores')")
    parser.add_argument("--frequencies", type=int, default=341)
    parser.add_argument("--amplitudes", type=int, default=36)
    parser.add_argument("--steps-per-period", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    chain = DrivenChain.from_materials(
        n_beads=1, bead_radius_m=9.525e-3, bead_mass_kg=0.028, bead_youngs_pa=193e9, bead_poisson=0.3,
        driver_youngs_pa=193e9, driver_poisson=0.3, wall_youngs_pa=193e9, wall_poisson=0.3,
        precompression_n=0.133, damping_rate_per_s=1800.0,
    )
    frequencies = jnp.linspace(3000.0, 4700.0, args.frequencies)
    amplitudes = jnp.linspace(0.683e-9, 6.66e-9, args.amplitudes)
    options = dict(steps_per_period=args.steps_per_period)

    def grid():
        return lockin_grid(chain, frequencies, amplitudes, **options).rms

    def model(theta):
        f0, kappa_scale, gamma_scale, drive_scale = theta
        c = eqx.tree_at(lambda c: (c.precompression_n, c.contact_kappa_n_m1p5, c.damping_rate_per_s), chain,
                        (f0, chain.contact_kappa_n_m1p5 * kappa_scale, chain.damping_rate_per_s * gamma_scale))
        return lockin_grid(c, frequencies, amplitudes * drive_scale, **options).rms[0]

    jacobian = jax.jit(jax.jacfwd(model))
    theta = jnp.array([0.133, 1.0, 1.0, 1.0])
    grid_first, grid_time = timed(grid, args.repeats)
    jac_first, jac_time = timed(lambda: jacobian(theta), args.repeats)
    runs = args.frequencies * args.amplitudes
    steps = 60 * args.steps_per_period
    result = {
        "label": args.label,
        "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg(), "platform": platform.platform(),
                    "devices": [str(d) for d in jax.devices()]},
        "grid": {"frequencies": args.frequencies, "amplitudes": args.amplitudes, "runs": runs,
                 "steps_per_run": steps, "bead_steps": runs * steps},
        "grid_s": grid_time,
        "grid_first_call_s": grid_first,
        "jacobian_4_params_s": jac_time,
        "jacobian_first_call_s": jac_first,
        "jacobian_over_grid": jac_time / grid_time,
        "bead_steps_per_s": runs * steps / grid_time,
        "check_peak_rms_m_s": float(np.max(np.asarray(grid()[0]))),
    }
    write_json(args.out, result)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
