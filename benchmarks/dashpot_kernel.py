"""What the rate slot's laws (a linear dashpot, velocity-squared dissipation) cost in the full
C++ kernel, and what they gain on the JAX kernel.

    taskset -c 1 python benchmarks/dashpot_kernel.py --label NAME --out FILE.json [--calls 30]
        [--rate-laws dashpot,velocity_squared]

The rate slot's terms are compiled into the full kernel only for runs that have a law there
(`chain_laws.h`, `kDashpot`, `RateSlotCoefficient`), so that damped runs without one keep
their speed. Measured, one process, medians of `--calls` warm calls:

- `posterior_gradient_ms`: the value and gradient of `benchmarks/posterior_bench.py`'s
  potential for 2 chains (10 traces of the paper's 21-bead chain, eta, mu, C and three
  sensor gains: one tangent run of 20 chains, 3 directions, no dashpot). Run it on two
  builds, alternately, on one core (`taskset -c 1`) to compare them.
- `dashpot_jacobian`: residual-like forces and `jax.jacfwd` in (eta, mu, dashpot) of 10
  chains of the paper's chain with a dashpot (20 N s/m), eta = 2 us and mu = 0.19, 1 ms at
  2 us sampling, on the default kernel and on the JAX kernel (`kernel="jax"`), with the
  largest difference between the two Jacobians relative to the largest entry.
- `velocity_squared_jacobian`: the same with velocity-squared dissipation
  (`laws.VelocitySquared`, c = 3000 N s^2/m^2) in the dashpot's place, in (eta, mu, c).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def _median_ms(function, argument, calls: int, step) -> float:
    """Median wall time (ms) of `calls` warm calls of `function` at `argument + i step`."""
    import jax

    jax.block_until_ready(function(argument))
    times = []
    for i in range(calls):
        began = time.perf_counter()
        jax.block_until_ready(function(argument + step * i))
        times.append(time.perf_counter() - began)
    return 1e3 * float(np.median(times))


def posterior_gradient_ms(calls: int) -> float:
    import jax
    import jax.numpy as jnp

    import fitting
    from fit_bench import benchmark_files
    from fitting.fit import FitWarning
    from fitting.parameters import transform_arrays
    from fitting.posterior import _laplace_whitening, _potential

    files, _, _ = benchmark_files(10)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fit = fitting.fit(files, ("eta_s", "mu", "C"), priors=["sensor_gain=+-2%"], covariance="noise",
                          progress=False, throw=False)
    problem = fit.problem
    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    z_hat, chol = _laplace_whitening(problem.instances, constants, np.asarray(fit.x), fit.covariance)
    potential = _potential(problem, constants, z_hat, chol)
    gradient = jax.jit(jax.vmap(jax.value_and_grad(potential)))
    return _median_ms(gradient, 0.1 * jnp.ones((2, len(problem.instances))), calls, 1e-3)


# The rate slot's laws as measured: the setup's law, its coefficient (the dashpot's in N s/m,
# velocity-squared dissipation's in N s^2/m^2) and how the Jacobian's timing loop moves it.
RATE_LAWS = {"dashpot": (20.0, 1e-3), "velocity_squared": (3000.0, 1e-1)}


def rate_slot_jacobian(law: str, calls: int) -> dict:
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import hertzchain as hc
    from hertzchain import native
    from hertzchain.batched import kernel_flags, record_batched
    from hertzchain.integrate import Recording

    coefficient, move = RATE_LAWS[law]
    slot = {"dashpot_n_s_m": coefficient} if law == "dashpot" else {
        "dissipation": (hc.laws.VelocitySquared(coefficient),)}
    base = hc.ChainSetup(21, eta_s=2e-6, mu=0.19, **slot)
    setup, _ = hc.batch_setup(base, striker_velocity_m_s=np.linspace(0.5, 2.0, 10))
    grid = hc.choose_time_grid(setup, t_end_s=1e-3, sample_interval_s=2e-6)
    flags = kernel_flags(setup)._replace(ledger=False)
    ones = jnp.ones(setup.eta_s.shape)
    where = (lambda s: s.dashpot_n_s_m) if law == "dashpot" else (lambda s: s.dissipation[2].c_n_s2_m2)

    def jacobian(kernel):
        def forces(q):
            changed = eqx.tree_at(lambda s: (s.eta_s, s.mu, where(s)), setup,
                                  (q[0] * ones, q[1] * ones, q[2] * ones))
            out = record_batched(changed, grid, Recording((5, 10)), flags, kernel=kernel)
            return jnp.stack([out.forces_n[name] for name in out.channel_names])

        return jax.jit(jax.jacfwd(forces))

    q = jnp.asarray([2e-6, 0.19, coefficient])
    default, reference = jacobian("auto"), jacobian("jax")
    a, b = np.asarray(default(q)), np.asarray(reference(q))
    scale = np.max(np.abs(b), axis=tuple(range(b.ndim - 1)))  # per parameter
    step = jnp.asarray([1e-10, 1e-5, move])  # the timing loop's moves, in each parameter's scale
    timed = {name: _median_ms(function, q, calls, step)
             for name, function in (("default", default), ("jax", reference))}
    return {"default_kernel_ms": timed["default"], "jax_kernel_ms": timed["jax"],
            "speedup": timed["jax"] / timed["default"],
            "max_jacobian_difference_relative": float(np.max(np.abs(a - b) / scale)),
            "chains": 10, "steps": grid.n_samples * grid.steps_per_sample, "coefficient": coefficient,
            "kernel": str(native.kernel_for(flags, None))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--label", required=True, help="which build this is (stored with the numbers)")
    parser.add_argument("--out", required=True, help="JSON output")
    parser.add_argument("--calls", type=int, default=30, help="timed calls per measurement [30]")
    parser.add_argument("--rate-laws", default="dashpot,velocity_squared",
                        help=f"which of {', '.join(RATE_LAWS)} to measure [all]")
    parser.add_argument("--no-posterior", action="store_true", help="skip posterior_gradient_ms")
    args = parser.parse_args(argv)
    laws = [name.strip() for name in args.rate_laws.split(",") if name.strip()]
    unknown = sorted(set(laws) - set(RATE_LAWS))
    if unknown:
        parser.error(f"--rate-laws: unknown {unknown}; choose from {', '.join(RATE_LAWS)}")
    from hertzchain.cli import expose_cpu_cores

    expose_cpu_cores()  # one device under `taskset -c 1`
    import hertzchain
    from fit_bench import machine_info
    from hertzchain.io.atomic import write_json

    result = {"label": args.label, "source": str(Path(hertzchain.__file__).parent)}
    if not args.no_posterior:
        result["posterior_gradient_ms"] = posterior_gradient_ms(args.calls)
    result |= {f"{law}_jacobian": rate_slot_jacobian(law, args.calls) for law in laws}
    result["machine"] = machine_info()
    write_json(args.out, result)
    print(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
