"""The measurements of `benchmarks/run.py`, each run in a process of its own (`run.py --worker`):
the standard case and its damped + frictional variant, the timing helper, and one worker per
kind of measurement (throughput of one implementation and size, gradient modes, the machine,
a whole fit, alternating hertzchain/Numba pairs, one fit iteration, the kernel's build).
Other benchmark scripts take the case and the timing helper from here."""

from __future__ import annotations

import math
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))


SIZES_N = (21, 200, 2000)
SIZES_B = (1, 64, 1024)
STANDARD = (21, 1024)
DT_S = 1e-6
STANDARD_STEPS = 2500
# Extra (hertzchain, Numba, plain JAX) triples run on the standard case for the ratios' spread.
STANDARD_PAIRS = 3
# solve_batched as users call it (fused kernel where built), with the books, with the JAX kernel
HERTZCHAIN_IMPLS = ("hertzchain", "hertzchain-books", "hertzchain-jax")
# implementations that split the batch over the CPU's cores as host devices
SHARDED_IMPLS = HERTZCHAIN_IMPLS + ("plain-jax",)
# rows of the table, the plot and the summary
LABELS = HERTZCHAIN_IMPLS + ("hertzchain-1dev", "plain-jax", "numba", "numpy")
# --quick: (hertzchain, Numba) pairs per case, each time the median of this many runs
QUICK_PAIRS = 4
QUICK_REPEATS = 5
# Bead-steps per timed run of the larger cases (fewer steps there, same physics per step).
WORK_PER_RUN = 2e8
# The damped + frictional case (the standard case with these): Kuwabara-Kono damping, s;
# track friction coefficient (deceleration mu g).
DAMPED_ETA_S = 2e-6
DAMPED_MU = 0.19


def _rss_mb() -> float:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def steps_for(n_beads: int, batch: int) -> int:
    """Steps timed for a size: the full 2.5 ms run unless that would take too long."""
    steps = WORK_PER_RUN / (n_beads * batch)
    return int(min(STANDARD_STEPS, max(100, 100 * round(steps / 100))))


def _case(n_beads: int, batch: int, steps: int, eta_s: float = 0.0, mu: float = 0.0):
    """The batched hertzchain setup, its grid and the arrays the baselines need."""
    import numpy as np

    import hertzchain as hc

    if batch == 1:
        values = {"striker_velocity_m_s": [0.3], "wall_youngs_pa": [203e9]}
    else:
        side = int(round(math.sqrt(batch)))
        values = {
            "striker_velocity_m_s": np.geomspace(0.1, 1.0, side),
            "wall_youngs_pa": np.geomspace(3e9, 400e9, batch // side),
        }
    setup, _ = hc.batch_setup(hc.ChainSetup(n_beads, eta_s=eta_s, mu=mu), **values)
    grid = hc.choose_time_grid(setup, t_end_s=steps * DT_S, sample_interval_s=DT_S, dt_s=DT_S)
    model = hc.build_model(hc.ChainSetup(n_beads))
    arrays = {
        "mass_kg": np.asarray(model.mass_kg),
        "kappa": np.asarray(model.kappa),
        "wall_kappa": np.asarray(jax_vmap_wall_kappa(setup)),
        "v0": np.asarray(setup.striker_velocity_m_s),
        "friction_decel_m_s2": mu * float(np.asarray(setup.gravity_m_s2)[0]),
    }
    rows = (n_beads // 2 - 1, n_beads // 2)
    return setup, grid, arrays, rows


def jax_vmap_wall_kappa(setup):
    import jax

    return jax.vmap(lambda s: s.wall_kappa())(setup)


def jax_devices(count: int):
    """The first `count` JAX devices (host devices on a CPU)."""
    import jax

    return jax.devices()[:count]


def _time(fn, repeats: int):
    """(first call s, median s, min s, max s) of `fn()` (which blocks until done)."""
    start = time.perf_counter()
    result = fn()
    first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    times.sort()
    return first, times[len(times) // 2], times[0], times[-1], result


# ------------------------------------------------------------------------------------------
# Workers (each runs in its own process)


def worker_throughput(impl: str, n_beads: int, batch: int, steps: int, devices: int, damped: bool = False) -> dict:
    import numpy as np

    base_rss = _rss_mb()
    eta, mu = (DAMPED_ETA_S, DAMPED_MU) if damped else (0.0, 0.0)
    setup, grid, arrays, rows = _case(n_beads, batch, steps, eta_s=eta, mu=mu)
    args = (arrays["mass_kg"], arrays["kappa"], arrays["wall_kappa"], arrays["v0"], DT_S, steps, rows)
    # runs of 0.05-0.1 s on a machine whose other core may be busy: the median of 11
    repeats = 11
    if impl in HERTZCHAIN_IMPLS:
        import jax

        from hertzchain.batched import solve_batched
        from hertzchain.integrate import Recording

        recording = Recording(tuple(rows))
        use = jax.devices()[:devices] if batch >= 2 * devices else None
        # "hertzchain": the baselines' work (three forces every step); "hertzchain-books":
        # also the largest force of every contact at every step and the energy balance
        books = impl == "hertzchain-books"
        # "hertzchain-jax": the JAX kernel (the reference) where the default runs the C++ one
        kernel = "jax" if impl == "hertzchain-jax" else "auto"

        def fn():
            out = solve_batched(setup, grid, recording, devices=use, books=books, kernel=kernel)
            return jax.block_until_ready(out.forces_n)

        first, median, low, high, result = _time(fn, repeats)
        forces = np.stack([np.asarray(result[k]) for k in result], axis=1)  # (B, 3, n)
        forces = np.transpose(forces, (2, 1, 0))  # (n, 3, B)
        from hertzchain import native
        from hertzchain.batched import kernel_flags, kernel_rows

        flags = kernel_flags(setup)._replace(ledger=books)
        ran = native.kernel_for(flags, use, kernel_rows(setup)) if kernel == "auto" else None
        native_kernel = ran or "none (JAX kernel)"
    elif impl == "plain-jax":
        import jax

        import baselines

        use = jax_devices(devices)

        def fn():  # as for hertzchain: the forces on the device, not copied into NumPy
            return jax.block_until_ready(baselines.plain_jax_batch(*args, devices=use, to_numpy=False))

        first, median, low, high, result = _time(fn, repeats)
        forces = np.asarray(result)
    elif impl == "hertzchain-solve":
        # The general solver on one chain (full energy ledger every sample), as `simulate` runs it.
        import jax

        from hertzchain.integrate import Recording, _solve_jit

        single = jax.tree_util.tree_map(lambda leaf: leaf[0], setup)
        recording = Recording(tuple(rows))

        def fn():
            return jax.block_until_ready(_solve_jit(single, grid, recording).forces_n)

        first, median, low, high, result = _time(fn, repeats)
        forces = np.stack([np.asarray(result[f"contact_{r}"]) for r in rows] + [np.asarray(result["wall"])], 1)
        forces = forces[:, :, None]
    elif damped:
        import baselines

        if not baselines.HAVE_NUMBA:
            return {"available": False, "reason": "numba is not installed"}
        if impl != "numba":
            return {"available": False, "reason": f"no damped variant of {impl}"}

        def fn():
            return baselines.numba_damped_batch(*args, eta_s=eta, friction_decel_m_s2=arrays["friction_decel_m_s2"])

        first, median, low, high, result = _time(fn, repeats)
        forces = result
    else:
        import baselines

        if impl.startswith("numba") and not baselines.HAVE_NUMBA:
            return {"available": False, "reason": "numba is not installed"}
        single = batch == 1
        fn_base = {
            ("numpy", True): baselines.numpy_single,
            ("numpy", False): baselines.numpy_batch,
            ("numba", True): baselines.numba_single,
            ("numba", False): baselines.numba_batch,
        }[(impl, single)]
        if single:
            args = (args[0], args[1], float(args[2][0]), float(args[3][0])) + args[4:]
        if impl == "numpy":
            repeats = 3 if n_beads * batch * steps < 5e7 else 1

        def fn():
            return fn_base(*args)

        first, median, low, high, result = _time(fn, repeats)
        forces = result if not single else result[:, :, None]
    bead_steps = n_beads * batch * steps
    return {
        **({"native_kernel": native_kernel} if impl in HERTZCHAIN_IMPLS else {}),
        "available": True,
        "impl": impl,
        "damped": damped,
        "n_beads": n_beads,
        "batch": batch,
        "steps": steps,
        "devices": devices if impl in SHARDED_IMPLS and batch % devices == 0 else (os.cpu_count() if impl == "numba" and batch > 1 else 1),
        "first_call_s": first,
        "run_s": median,
        "run_min_s": low,
        "run_max_s": high,
        "compile_s": max(first - median, 0.0),
        "bead_steps_per_s": bead_steps / median,
        "peak_rss_mb": _peak_rss_mb() - base_rss,
        "checksum_wall_max_n": float(np.max(forces[:, 2, :])),
        "wall_peak_n": np.max(forces[:, 2, :], axis=0)[:8].tolist(),
    }


def worker_gradient() -> dict:
    """Derivatives of a trace loss against its forward run: forward mode (`jax.jacfwd`, with
    respect to eta alone and to eta, v0 and Y_wall together) and reverse mode (`jax.grad`
    with respect to eta, through `solve`'s checkpointed scans and with checkpointing off)."""
    import jax
    import jax.numpy as jnp

    import hertzchain as hc
    import hertzchain.integrate as integrate
    from hertzchain.integrate import Recording, solve

    eta_true, eta = 2e-6, 1.5e-6
    recording = Recording(())
    start3 = jnp.asarray([eta, 0.3, 203e9])  # eta s, striker velocity m/s, wall modulus Pa

    def case(t_end_s):
        grid = hc.choose_time_grid(hc.ChainSetup(21, eta_s=eta), t_end_s=t_end_s, sample_interval_s=DT_S, dt_s=DT_S)
        target = solve(hc.ChainSetup(21, eta_s=eta_true), grid, recording).forces_n["wall"]

        def loss3(q):
            setup = hc.ChainSetup(21, eta_s=q[0], striker_velocity_m_s=q[1], wall_youngs_pa=q[2])
            return jnp.sum((solve(setup, grid, recording).forces_n["wall"] - target) ** 2)

        return grid, loss3, lambda eta_s: loss3(start3.at[0].set(eta_s))

    def measure(grid, loss, derivative, x, value_of):
        forward, grad = jax.jit(loss), jax.jit(derivative)
        # runs of 0.5-40 ms: medians of 21 (7 left the 2500-step ratio scattered 2.2-3.9)
        _, f_med, *_ = _time(lambda: jax.block_until_ready(forward(x)), 21)
        g_first, g_med, *_ = _time(lambda: jax.block_until_ready(grad(x)), 21)
        row = {
            "steps": grid.n_steps,
            "forward_s": f_med,
            "grad_s": g_med,
            "grad_over_forward": g_med / f_med,
            "grad_compile_s": max(g_first - g_med, 0.0),
            "forward_temp_mb": forward.lower(x).compile().memory_analysis().temp_size_in_bytes / 2**20,
            "grad_temp_mb": grad.lower(x).compile().memory_analysis().temp_size_in_bytes / 2**20,
        }
        g_value = value_of(grad(x))
        step = 1e-3 * eta
        e = jnp.zeros_like(x).at[0].set(step) if x.ndim else step
        fd = float((forward(x + e) - forward(x - e)) / (2 * step))
        row.update(grad=g_value, finite_difference=fd, relative_difference_to_fd=abs(g_value - fd) / abs(fd))
        return row

    results = {}
    x1 = jnp.asarray(eta)
    for t_end in (2.5e-3, 10e-3):
        grid, loss3, loss = case(t_end)
        tag = f"{t_end * 1e3:g}ms"
        results[f"forward_mode_{tag}"] = measure(grid, loss, jax.jacfwd(loss), x1, float)
        results[f"forward_mode_3params_{tag}"] = measure(grid, loss3, jax.jacfwd(loss3), start3, lambda g: float(g[0]))
    for label, checkpointed in (("checkpointed", True), ("plain", False)):
        original = integrate.jax.checkpoint
        if not checkpointed:
            integrate.jax.checkpoint = lambda fn, **_: fn
        try:
            for t_end in (2.5e-3, 10e-3):
                grid, _, loss = case(t_end)
                results[f"{label}_{t_end * 1e3:g}ms"] = measure(grid, loss, jax.grad(loss), x1, float)
        finally:
            integrate.jax.checkpoint = original
    return results


def worker_machine() -> dict:
    """The machine's rate: f64 FMA throughput (dgemm) and sqrt throughput on all cores."""
    import numpy as np

    info = {"cpu": platform.processor() or "", "cores": os.cpu_count()}
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        for line in lscpu.splitlines():
            if line.startswith("Model name:"):
                info["cpu"] = line.split(":", 1)[1].strip()
            if line.startswith("Flags:"):
                flags = line.split()
                info["vector"] = (
                    "AVX-512" if "avx512f" in flags else "AVX2+FMA" if "avx2" in flags else "SSE"
                )
                info["cpu_flags"] = " ".join(flags[1:])
    except OSError:
        pass
    n = 2000
    a = np.random.default_rng(0).standard_normal((n, n))
    a @ a
    start = time.perf_counter()
    for _ in range(3):
        a @ a
    info["dgemm_gflop_s"] = 3 * 2 * n**3 / (time.perf_counter() - start) / 1e9
    try:
        import numba

        @numba.njit(parallel=True, fastmath=True)
        def hertz_core(d, k, repeats):
            total = 0.0
            for r in numba.prange(repeats):
                acc = 0.0
                for i in range(d.shape[0]):
                    p = max(d[i] + r * 1e-9, 0.0)
                    acc += k * p * np.sqrt(p)
                total += acc
            return total

        d = np.random.default_rng(1).random(2048)
        hertz_core(d, 1.0, 4)
        repeats = 20000
        start = time.perf_counter()
        hertz_core(d, 1.0, repeats)
        info["hertz_core_per_s"] = d.size * repeats / (time.perf_counter() - start)
    except ImportError:
        info["hertz_core_per_s"] = None
    # A bead-step is ~10 flops + 1 sqrt: bounded by the FMA rate / 10 and by the rate of the
    # Hertz core (max, sqrt, 2 mul, add: one per bead-step, the sqrt being the slow part).
    limits = [info["dgemm_gflop_s"] * 1e9 / 10.0]
    if info.get("hertz_core_per_s"):
        limits.append(info["hertz_core_per_s"])
    info["limit_bead_steps_per_s"] = min(limits)
    return info


def worker_fit() -> dict:
    """One fit of eta, mu, C on 10 synthetic traces and one diagnosis, with what `fitting` provides."""
    try:
        import fitting
        from fitting.synthetic import paper_setups, synthetic_traces
    except ImportError as error:
        return {"available": False, "reason": f"fitting not available: {error}"}
    import numpy as np

    truth = {"eta_s": 2e-6, "mu": 0.19}
    velocities = np.linspace(0.15, 0.6, 10)
    t_end = 2.5e-3
    files = synthetic_traces(
        paper_setups(velocities, **truth), contacts=(6, 11), t_end_s=t_end, sample_interval_s=2e-6,
        noise_std_n=0.3, seed=1,
    )
    result = {"available": True, "n_traces": len(files), "t_end_s": t_end, "truth": truth}
    start = time.perf_counter()
    fitted = fitting.fit(files, ("eta_s", "mu", "C"), progress=False, throw=False)
    result["fit_s"] = time.perf_counter() - start
    result["fit_values"] = {k: float(v) for k, v in dict(fitted.values).items()}
    result["fit_stderr"] = {k: float(v) for k, v in dict(fitted.stderr).items()}
    result["fit_converged"] = bool(fitted.converged)
    result["fit_steps"] = int(fitted.n_steps)
    try:
        from fitting.diagnosis import diagnose
    except ImportError as error:
        result["diagnosis"] = {"available": False, "reason": str(error)}
        return result
    start = time.perf_counter()
    diagnosis = diagnose(files[:3], progress=False)
    result["diagnosis"] = {
        "available": True,
        "n_traces": 3,
        "wall_s": time.perf_counter() - start,
        "summary": str(getattr(diagnosis, "effects", diagnosis))[:500],
    }
    return result


def worker_pairs(damped: bool, pairs: int, repeats: int) -> dict:
    """The standard case (conservative, or damped + frictional), hertzchain as users call it
    (`solve_batched`, books off, the batch over the host devices) and the Numba kernel of the
    same physics, timed in turn in one process, `pairs` times (medians of `repeats` runs
    each): neighbouring timings share the machine's load. Returns the bead-steps/s of each
    and their ratios, and the largest difference of the two's wall forces."""
    import jax
    import numpy as np

    import baselines
    from hertzchain import native
    from hertzchain.batched import kernel_flags, kernel_rows, solve_batched
    from hertzchain.integrate import Recording

    if not baselines.HAVE_NUMBA:
        return {"available": False, "reason": "numba is not installed"}
    n, b = STANDARD
    eta, mu = (DAMPED_ETA_S, DAMPED_MU) if damped else (0.0, 0.0)
    setup, grid, arrays, rows = _case(n, b, STANDARD_STEPS, eta_s=eta, mu=mu)
    args = (arrays["mass_kg"], arrays["kappa"], arrays["wall_kappa"], arrays["v0"], DT_S, STANDARD_STEPS, rows)
    recording = Recording(tuple(rows))
    devices = jax.devices()
    use = devices if len(devices) > 1 else None

    def ours():
        out = solve_batched(setup, grid, recording, devices=use, books=False)
        return jax.block_until_ready(out.forces_n)

    def ours_one_device():  # the default call: one device, the kernel's blocks over the cores
        out = solve_batched(setup, grid, recording, books=False)
        return jax.block_until_ready(out.forces_n)

    def numba():
        if damped:
            return baselines.numba_damped_batch(*args, eta_s=eta, friction_decel_m_s2=arrays["friction_decel_m_s2"])
        return baselines.numba_batch(*args)

    # with several host devices, the default call (one device) is timed too
    one_device = use is not None
    ours_first, _, _, _, forces = _time(ours, 1)
    one_first, _, _, _, forces_one = _time(ours_one_device, 1) if one_device else (None, 0, 0, 0, forces)
    numba_first, _, _, _, reference = _time(numba, 1)
    runs = []
    work = n * b * STANDARD_STEPS
    for _ in range(pairs):
        a = _time(ours, repeats)[1]
        d = _time(ours_one_device, repeats)[1] if one_device else None
        c = _time(numba, repeats)[1]
        runs.append({"hertzchain": work / a, "numba": work / c, "ratio": c / a})
        if one_device:
            runs[-1].update(hertzchain_one_device=work / d, ratio_one_device=c / d)
    wall = np.asarray(forces["wall"])  # (B, n)
    ratios = [r["ratio"] for r in runs]
    return {
        "available": True,
        "case": f"N={n}, B={b}, {STANDARD_STEPS} steps of 1 us, 3 forces every step"
        + (f", eta = {eta * 1e6:g} us, mu = {mu}" if damped else ", dissipationless"),
        "native_kernel": native.kernel_for(kernel_flags(setup)._replace(ledger=False), use, kernel_rows(setup)) or "none (JAX kernel)",
        "host_devices": len(devices),
        "numba_threads": numba_threads(),
        "kernel_march": os.environ.get(native.ARCH_VARIABLE, "native"),
        "numba_cpu_name": os.environ.get("NUMBA_CPU_NAME", "host"),
        "numba_cpu_features": os.environ.get("NUMBA_CPU_FEATURES", "host"),
        "hertzchain_over_numba": float(np.median(ratios)),
        "hertzchain_one_device_over_numba": float(np.median([r["ratio_one_device"] for r in runs]))
        if one_device else None,
        "runs": runs,
        "first_call_s": {"hertzchain": ours_first, "hertzchain_one_device": one_first, "numba": numba_first},
        "wall_force_max_difference_n": float(np.max(np.abs(wall.T - reference[:, 2, :]))),
        "one_device_equals_sharded": bool(np.array_equal(np.asarray(forces_one["wall"]), wall)),
        "wall_force_max_n": float(np.max(wall)),
    }


def numba_threads() -> int | None:
    try:
        import numba

        return int(numba.get_num_threads())
    except ImportError:
        return None


def fit_bench_traces(n_traces: int = 10) -> list:
    """The fit benchmarks' data: `n_traces` synthetic traces of the paper's chain (impact
    speeds 0.15-0.6 m/s, eta 2 us, mu 0.19, contacts 6 and 11 and the wall, 2.5 ms at 2 us,
    noise 0.3 N)."""
    import numpy as np

    from fitting.synthetic import paper_setups, synthetic_traces

    return synthetic_traces(paper_setups(np.linspace(0.15, 0.6, n_traces)), contacts=(6, 11), t_end_s=2.5e-3,
                            sample_interval_s=2e-6, noise_std_n=0.3, seed=1)


def worker_fit_iteration() -> dict:
    """One fit iteration as `fitting` runs it (whitened residuals and their Jacobian in eta,
    mu, C: `residuals_and_jacobian`) on 10 synthetic traces of the paper's chain (0.15-0.6
    m/s, eta 2 us, mu 0.19, contacts 6 and 11 and the wall, 2.5 ms at 2 us), against one
    conservative forward run of the same 10 chains (`solve_batched`, books off, eta = mu = 0)
    on the fit's own time grid. Kernels as the environment selects them
    (`HERTZCHAIN_NATIVE=0`: the JAX kernel)."""
    try:
        from fitting.fit import initial_values, make_problem
        from fitting.model import residuals_and_jacobian
    except ImportError as error:
        return {"available": False, "reason": f"fitting not available: {error}"}
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    from hertzchain import native
    from hertzchain.batched import solve_batched

    files = fit_bench_traces()
    problem = make_problem(files, ("eta_s", "mu", "C"))
    x = jnp.asarray(initial_values(problem))
    first, median, low, high, (r, jac) = _time(lambda: residuals_and_jacobian(problem, x), 7)
    group = problem.groups[0]
    zeros = jnp.zeros_like(group.setups.eta_s)
    conservative = eqx.tree_at(lambda s: (s.eta_s, s.mu), group.setups, (zeros, zeros))

    def forward():
        out = solve_batched(conservative, group.grid, group.recording, books=False)
        return jax.block_until_ready(out.forces_n)

    f_first, f_median, *_ = _time(forward, 11)
    return {
        "available": True,
        "native": native.unavailable_reason() is None,
        "n_traces": len(files),
        "n_steps": group.grid.n_steps,
        "n_beads": int(group.setups.n_beads),
        "n_residuals": int(np.size(r)),
        "iteration_s": median,
        "iteration_min_s": low,
        "iteration_max_s": high,
        "iteration_compile_s": max(first - median, 0.0),
        "conservative_forward_s": f_median,
        "iteration_over_forward": median / f_median,
        "jacobian_columns": [float(np.linalg.norm(col)) for col in np.asarray(jac).T],
        "residual_norm": float(np.linalg.norm(r)),
    }


def worker_build() -> dict:
    """Build (or find) the fused kernel: the seconds it took, or why it is unavailable."""
    start = time.perf_counter()
    from hertzchain import native

    reason = native.unavailable_reason()
    return {"available": reason is None, "reason": reason, "build_or_load_s": time.perf_counter() - start}


WORKERS = {
    "throughput": worker_throughput,
    "gradient": worker_gradient,
    "machine": worker_machine,
    "fit": worker_fit,
    "fit_iteration": worker_fit_iteration,
    "build": worker_build,
    "pairs": worker_pairs,
}
