"""Time a full single-bead lock-in grid and its Jacobian (Lydon et al. 2015's grid).

    python benchmarks/driven_bench.py --out benchmarks/results/driven_bench/latest.json [--label TEXT]
                                      [--frequencies 341] [--amplitudes 36] [--steps-per-period 64]

The grid: one 19.05 mm, 28 g steel bead between steel faces (Hertz sphere-flat), F0 = 0.133 N,
damping 1800 /s; 341 frequencies 3.0-4.7 kHz × 36 drive amplitudes 0.68-6.66 nm; ramp 25, hold
35, window 4 periods (60 periods a run). Times (median of `--repeats` after compilation): the
grid (`lockin_grid`, RMS and phase at f and f/2) and its Jacobian with respect to four
parameters (precompression, contact-stiffness scale, damping rate, drive scale) by
`jax.jacfwd`, as wall time and as this process's CPU time, on each kernel in turn in one
process: the fused host kernel (`kernel="auto"`, `hertzchain.driven.fused`; where it cannot
run here, "auto" is the JAX kernel and says so) and the JAX kernel (`kernel="jax"`), with
the largest difference between their grids and Jacobians. The JSON records the machine (CPU
count, load average) with the numbers.

Physics checks are stored with them (`checks`): for the single bead as the research notes
fitted it (delta_0 = 22.6 nm at F0 = 0.133 N, zeta = 0.036, drive scale 1.12), the resonance
shift from the lowest to the highest drive and the fall of the peak velocity per nm of drive
(their independent model: -6.5 % and 0.87) and the period-doubling threshold at 7.9 kHz from
the Floquet multipliers (their model: 12 nm); and the largest
difference between the ramped runs of `lockin_grid` and a phase-continuous upward frequency
sweep (`lockin_schedule`) at 6.66 nm over 0.86-1.06 of the linear resonance, relative to
the peak (both held until transients decay to 1e-6, `settle_periods`).
"""

from __future__ import annotations

import argparse
import functools
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
from hertzchain.driven import (
    DrivenChain,
    HarmonicSchedule,
    lockin_grid,
    lockin_schedule,
    period_doubling_threshold,
    settle_periods,
)
from hertzchain.driven import fused


def timed(function, repeats: int) -> tuple[float, float, float]:
    """(first call incl. compilation, median wall time and median CPU time of this process
    over `repeats` later calls), s. On a shared machine the CPU time is the steadier figure."""
    start = time.perf_counter()
    jax.block_until_ready(function())
    first = time.perf_counter() - start
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        jax.block_until_ready(function())
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return first, statistics.median(wall), statistics.median(cpu)


def physics_checks() -> dict:
    """The tongue tip and the ramp-vs-sweep agreement (see the module docstring)."""
    kappa = 0.133 / (22.6e-9) ** 1.5
    fitted = DrivenChain(bead_mass_kg=[0.028], contact_kappa_n_m1p5=[kappa, kappa], precompression_n=0.133,
                         damping_rate_per_s=2 * 0.036 * 2 * np.pi * 3993.0)
    threshold = period_doubling_threshold(fitted, 7900.0, np.linspace(2e-9, 40e-9, 20))
    bending_hz = np.arange(3000.0, 4700.1, 5.0)
    drives = 1.12 * np.array([0.683e-9, 6.66e-9])
    rms = np.asarray(lockin_grid(fitted, bending_hz, drives, harmonics=(1.0,)).rms[0])
    peak_hz = bending_hz[np.argmax(rms, axis=0)]
    gain = rms.max(axis=0) / drives
    chain = DrivenChain.from_materials(
        n_beads=1, bead_radius_m=9.525e-3, bead_mass_kg=0.028, bead_youngs_pa=193e9, bead_poisson=0.3,
        driver_youngs_pa=193e9, driver_poisson=0.3, wall_youngs_pa=193e9, wall_poisson=0.3,
        precompression_n=0.133, damping_rate_per_s=1280.0,
    )
    linear_hz = float(np.sqrt(float(jnp.sum(chain.contact_stiffness_n_m())) / 0.028) / (2 * np.pi))
    frequencies = linear_hz * np.linspace(0.86, 1.06, 21)
    hold = settle_periods(chain, frequencies.max(), tolerance=1e-6)
    up = lockin_schedule(chain, HarmonicSchedule.levels(frequencies, 6.66e-9, periods_per_level=hold),
                         harmonics=(1.0,)).complex_amplitude[0, :, 0]
    ramped = lockin_grid(chain, frequencies, [6.66e-9], harmonics=(1.0,), hold_periods=hold).complex_amplitude[0, :, 0]
    return {
        "fitted_bead_resonance_shift": float(peak_hz[1] / peak_hz[0] - 1),
        "fitted_bead_resonance_shift_independent_model": -0.065,
        "fitted_bead_peak_per_nm_top_over_lowest": float(gain[1] / gain[0]),
        "fitted_bead_peak_per_nm_top_over_lowest_independent_model": 0.87,
        "tongue_tip_threshold_at_7900_hz_m": threshold,
        "tongue_tip_independent_model_m": 12e-9,
        "ramp_vs_upward_sweep_max_difference_over_peak": float(jnp.max(jnp.abs(ramped - up)) / jnp.max(jnp.abs(up))),
        "ramp_vs_upward_sweep_linear_resonance_hz": linear_hz,
        "ramp_vs_upward_sweep_peak_at_hz": float(frequencies[int(jnp.argmax(jnp.abs(up)))]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="JSON file to write")
    parser.add_argument("--label", default="", help="what the machine was doing (e.g. 'loaded, shared 2 cores')")
    parser.add_argument("--frequencies", type=int, default=341)
    parser.add_argument("--amplitudes", type=int, default=36)
    parser.add_argument("--steps-per-period", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-checks", action="store_true", help="timings only")
    args = parser.parse_args()

    chain = DrivenChain.from_materials(
        n_beads=1, bead_radius_m=9.525e-3, bead_mass_kg=0.028, bead_youngs_pa=193e9, bead_poisson=0.3,
        driver_youngs_pa=193e9, driver_poisson=0.3, wall_youngs_pa=193e9, wall_poisson=0.3,
        precompression_n=0.133, damping_rate_per_s=1800.0,
    )
    frequencies = jnp.linspace(3000.0, 4700.0, args.frequencies)
    amplitudes = jnp.linspace(0.683e-9, 6.66e-9, args.amplitudes)
    options = {"steps_per_period": args.steps_per_period}

    def model(theta, kernel):
        f0, kappa_scale, gamma_scale, drive_scale = theta
        c = eqx.tree_at(lambda c: (c.precompression_n, c.contact_kappa_n_m1p5, c.damping_rate_per_s), chain,
                        (f0, chain.contact_kappa_n_m1p5 * kappa_scale, chain.damping_rate_per_s * gamma_scale))
        return lockin_grid(c, frequencies, amplitudes * drive_scale, kernel=kernel, **options).rms[0]

    theta = jnp.array([0.133, 1.0, 1.0, 1.0])
    runs = args.frequencies * args.amplitudes
    steps = 60 * args.steps_per_period
    result = {
        "label": args.label,
        "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg(), "platform": platform.platform(),
                    "devices": [str(d) for d in jax.devices()]},
        "grid": {"frequencies": args.frequencies, "amplitudes": args.amplitudes, "runs": runs,
                 "steps_per_run": steps, "bead_steps": runs * steps},
        "fused_kernel_unavailable_reason": fused.unavailable_reason(),
        "kernels": {},
    }
    outputs = {}
    for kernel in ("auto", "jax"):
        def grid(kernel=kernel):
            return lockin_grid(chain, frequencies, amplitudes, kernel=kernel, **options).rms

        jacobian = jax.jit(jax.jacfwd(functools.partial(model, kernel=kernel)))
        grid_first, grid_time, grid_cpu = timed(grid, args.repeats)
        jac_first, jac_time, jac_cpu = timed(lambda: jacobian(theta), args.repeats)
        outputs[kernel] = (np.asarray(grid()), np.asarray(jacobian(theta)))
        result["kernels"]["fused" if kernel == "auto" and fused.runs("velocity") else kernel] = {
            "grid_s": grid_time,
            "grid_cpu_s": grid_cpu,
            "grid_first_call_s": grid_first,
            "jacobian_4_params_s": jac_time,
            "jacobian_4_params_cpu_s": jac_cpu,
            "jacobian_first_call_s": jac_first,
            "jacobian_over_grid": jac_time / grid_time,
            "bead_steps_per_s": runs * steps / grid_time,
            "check_peak_rms_m_s": float(np.max(outputs[kernel][0][0])),
        }
    (grid_auto, jac_auto), (grid_jax, jac_jax) = outputs["auto"], outputs["jax"]
    result["grid_max_difference_over_peak"] = float(np.max(np.abs(grid_auto - grid_jax)) / np.max(np.abs(grid_jax)))
    result["jacobian_max_difference_over_largest_entry"] = [
        float(np.max(np.abs(jac_auto[..., i] - jac_jax[..., i])) / np.max(np.abs(jac_jax[..., i])))
        for i in range(theta.size)]
    if "fused" in result["kernels"]:
        fast, slow = result["kernels"]["fused"], result["kernels"]["jax"]
        result["jax_over_fused"] = {"grid": slow["grid_s"] / fast["grid_s"],
                                    "jacobian": slow["jacobian_4_params_s"] / fast["jacobian_4_params_s"]}
    if not args.no_checks:
        result["checks"] = physics_checks()
    write_json(args.out, result)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
