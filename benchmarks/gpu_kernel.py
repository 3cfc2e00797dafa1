"""hertzchain's kernels on a GPU against a plain one-thread-per-chain CUDA kernel, and a fit.

    python benchmarks/gpu_kernel.py --out gpu_kernel.json [--sizes 100000] [--budget-s 330]

Every item is timed on its own and fails on its own (its error is written in its place and
the run goes on); the JSON is rewritten after each item, so an interrupted run keeps what
it measured. Items:

1. `cuda_build`: building (or loading from the cache) the one-thread-per-chain CUDA kernel
   of `hertzchain.native` for the bench chain (nvcc, once per machine and chain length).
2. `jax_*`: `solve_batched(..., kernel="jax", books=False)` (the JAX kernel) on the paper's
   chain, N = 21, f64, dt = 1 us, 2500 steps, three forces every step, B chains (impact
   velocities 0.1-1 m/s x wall moduli 3-400 GPa); `damped`: eta = 2 us, mu = 0.19.
3. `hertzchain_*`: the same with `kernel="auto"`: on a GPU the one-thread-per-chain CUDA
   kernel (`chain_kernel_thread.cu`); its forces are compared with the JAX kernel's.
   `kernel_*`: that kernel jitted alone on arrays already on the device (`native.run`,
   `native.run_full`, traces transposed to (B, samples)), and the set-up time before it.
4. `cuda_*`: a plain CUDA kernel of the same physics (CuPy `RawKernel`): one thread per
   chain, the chain's state in registers (N fixed at compile time), the whole trajectory in
   one launch, the three forces of every step written to a (steps, 3, B) buffer
   (neighbouring threads write neighbouring addresses). Its wall peaks are checked against
   the JAX kernel's.
5. `fit`: `fitting.fit` of eta, mu, C on 10 synthetic traces of the paper's chain (as
   `benchmarks/run.py`'s fit), wall time of the whole call, cold (with compilation) and
   warm, on the default device; `fit_cpu_2cores` (GPU machines): the same fit in a child
   process on 2 of the machine's CPU cores (`taskset`, JAX on the CPU, the host kernel).

Without a GPU (JAX on the CPU, no CuPy) the JAX items run with small B and the CUDA items
report why they cannot run. Prints progress; the default budget keeps the run under 6 min.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from run_workers import _time, fit_bench_traces  # noqa: E402  (_time: first call s, median s, min s, max s, result)

N_BEADS = 21
DT_S = 1e-6
STEPS = 2500
ETA_S = 2e-6
MU = 0.19

# The plain CUDA kernel: velocity Verlet with the laws of `hertzchain.contact` (Hertz,
# Kuwabara-Kono clipped at 0, track friction kicks), bodies 0..N (striker and beads),
# contacts 0..N (the last one the wall's). DAMPED selects damping and friction.
CUDA_SOURCE = r"""
#define NB (N_BEADS + 1)
__device__ __forceinline__ double kick(double w, double loss) {
    double s = fabs(w) - loss;
    s = s > 0.0 ? s : 0.0;
    return w > 0.0 ? s : (w < 0.0 ? -s : 0.0);
}
__device__ __forceinline__ double force(double d, double rate, double k, double c) {
    if (d <= 0.0) return 0.0;
    double r = sqrt(d);
    double f = k * d * r;
#if DAMPED
    f = fmax(f + c * k * r * rate, 0.0);
#endif
    return f;
}
extern "C" __global__ void chain(const double* inv_mass, const double* kappa, const double* wall_kappa,
                                 const double* v0, double dt, int steps, int r0, int r1, double c,
                                 double loss, double* out, int batch) {
    int j = blockIdx.x * blockDim.x + threadIdx.x;
    if (j >= batch) return;
    double x[NB], v[NB], a[NB];
#pragma unroll
    for (int i = 0; i < NB; ++i) { x[i] = 0.0; v[i] = 0.0; a[i] = 0.0; }
    v[0] = v0[j];
    double kw = wall_kappa[j], h = 0.5 * dt;
    for (int n = 0; n < steps; ++n) {
        double p[NB];
#pragma unroll
        for (int i = 0; i < NB; ++i) {
            double w = v[i] + h * a[i];
#if DAMPED
            w = kick(w, loss);
#endif
            x[i] += dt * w;
            p[i] = w + h * a[i];
            v[i] = w;
        }
        double before = 0.0;
#pragma unroll
        for (int i = 0; i < NB; ++i) {
            double d = i + 1 < NB ? x[i] - x[i + 1] : x[i];
            double rate = i + 1 < NB ? p[i] - p[i + 1] : p[i];
            double f = force(d, rate, i + 1 < NB ? kappa[i] : kw, c);
            a[i] = (before - f) * inv_mass[i];
            double w = v[i] + h * a[i];
#if DAMPED
            w = kick(w, loss);
#endif
            v[i] = w;
            before = f;
        }
        out[((long)n * 3 + 0) * batch + j] = force(x[r0] - x[r0 + 1], v[r0] - v[r0 + 1], kappa[r0], c);
        out[((long)n * 3 + 1) * batch + j] = force(x[r1] - x[r1 + 1], v[r1] - v[r1 + 1], kappa[r1], c);
        out[((long)n * 3 + 2) * batch + j] = force(x[NB - 1], v[NB - 1], kw, c);
    }
}
"""


def _case(batch: int, damped: bool):
    import numpy as np

    import hertzchain as hc

    side = max(1, int(round(math.sqrt(batch))))
    setup, _ = hc.batch_setup(
        hc.ChainSetup(N_BEADS, eta_s=ETA_S if damped else 0.0, mu=MU if damped else 0.0),
        striker_velocity_m_s=np.geomspace(0.1, 1.0, side),
        wall_youngs_pa=np.geomspace(3e9, 400e9, max(1, batch // side)),
    )
    grid = hc.choose_time_grid(setup, t_end_s=STEPS * DT_S, sample_interval_s=DT_S, dt_s=DT_S)
    return setup, grid


def item_hertzchain(batch: int, damped: bool, repeats: int, kernel: str, reference: dict | None = None) -> dict:
    """`solve_batched` with `kernel` ("auto": the fused kernel `native.kernel_for` picks, on a
    GPU the one-thread-per-chain CUDA kernel; "jax": the JAX kernel)."""
    import jax
    import numpy as np

    from hertzchain import native
    from hertzchain.batched import batch_size, kernel_flags, kernel_rows, solve_batched
    from hertzchain.integrate import Recording

    setup, grid = _case(batch, damped)
    chains = batch_size(setup)
    recording = Recording((N_BEADS // 2 - 1, N_BEADS // 2))
    fused = native.kernel_for(kernel_flags(setup)._replace(ledger=False), None, kernel_rows(setup)) if kernel == "auto" else None

    def run():
        out = solve_batched(setup, grid, recording, books=False, kernel=kernel)
        return jax.block_until_ready(out.forces_n)

    first, median, _, _, forces = _time(run, repeats)
    row = {
        "kernel": f"{fused.physics} on {fused.backend}" if fused else "jax", "batch": chains, "steps": grid.n_steps,
        "run_s": median, "compile_s": max(first - median, 0.0),
        "bead_steps_per_s": N_BEADS * chains * grid.n_steps / median,
        "wall_peak_n": np.max(np.asarray(forces["wall"]), axis=1)[:8].tolist(),
    }
    if reference and "wall_peak_n" in reference:  # the largest relative difference of all forces
        other = solve_batched(setup, grid, recording, books=False, kernel="jax")
        row["force_relative_difference_to_jax"] = max(
            float(np.max(np.abs(np.asarray(forces[k]) - np.asarray(other.forces_n[k]))))
            / float(np.max(np.abs(np.asarray(other.forces_n[k])))) for k in forces)
    return row


def item_kernel_alone(batch: int, damped: bool, repeats: int) -> dict:
    """The fused kernel `native.kernel_for` picks, jitted alone on the chains' arrays already
    on the device (the traces transposed to (B, samples) included), and the time
    `solve_batched` spends before it (the chains' arrays from the setups)."""
    import jax

    from hertzchain import native
    from hertzchain.batched import _initial, _Layout, _start, kernel_flags, kernel_params, kernel_rows, share_uniform

    setup, grid = _case(batch, damped)
    flags = kernel_flags(setup)._replace(ledger=False)
    fused = native.kernel_for(flags, None, kernel_rows(setup))
    if fused is None:
        return {"error": "no fused kernel for this device"}
    start = time.perf_counter()
    p = jax.block_until_ready(share_uniform(kernel_params(setup)))
    prepare_s = time.perf_counter() - start
    layout = _Layout(p["mass"].shape[0])
    options = dict(dt_s=grid.dt_s, steps_per_sample=grid.steps_per_sample, n_samples=grid.n_samples,
                   channels=(N_BEADS // 2 - 1, N_BEADS // 2, layout.bodies - 1), preload=False, springs=False,
                   backend=fused.backend)
    if fused.physics == "full":
        x, v, a, _, _ = _start(p, flags)
        kernel = jax.jit(lambda p, x, v, a: native.run_full(p, x, v, a, viscous=flags.viscous, friction=flags.friction,
                                                            **options))
        arguments = (p, x, v, a)
    else:
        state, _, _ = _initial(p, flags, layout, grid.dt_s)
        kernel = jax.jit(lambda p, s: native.run(p, s, books=False, **options)[0])
        arguments = (p, state)
    first, median, _, _, _ = _time(lambda: jax.block_until_ready(kernel(*arguments)), repeats)
    chains = int(p["v0"].shape[-1])
    return {"kernel": f"{fused.physics} on {fused.backend}", "batch": chains, "steps": grid.n_steps,
            "prepare_s": prepare_s, "run_s": median, "compile_s": max(first - median, 0.0),
            "bead_steps_per_s": N_BEADS * chains * grid.n_steps / median}


def item_cuda_build() -> dict:
    """The one-thread-per-chain CUDA kernel built for the bench chain (once per machine)."""
    from hertzchain import native

    reason = native.thread_unavailable_reason("cuda")
    if reason is not None:
        return {"error": reason}
    start = time.perf_counter()
    target = native._thread_target("cuda", N_BEADS + 2, "forward")
    return {"build_or_load_s": time.perf_counter() - start, "target": target}


def item_cuda(batch: int, damped: bool, repeats: int, reference: dict | None) -> dict:
    import cupy as cp
    import numpy as np

    import hertzchain as hc

    setup, grid = _case(batch, damped)
    model = hc.build_model(hc.ChainSetup(N_BEADS))
    import jax

    wall = np.asarray(jax.vmap(lambda s: s.wall_kappa())(setup), dtype=float)
    chains = wall.size
    rows = (N_BEADS // 2 - 1, N_BEADS // 2)
    kernel = cp.RawKernel(CUDA_SOURCE, "chain",
                          options=(f"-DN_BEADS={N_BEADS}", f"-DDAMPED={int(damped)}", "-std=c++14"))
    inv_mass = cp.asarray(1.0 / np.asarray(model.mass_kg))
    kappa = cp.asarray(np.asarray(model.kappa))
    wall_d = cp.asarray(wall)
    v0 = cp.asarray(np.asarray(setup.striker_velocity_m_s, dtype=float))
    out = cp.empty((grid.n_steps, 3, chains))
    threads = 128
    blocks = (chains + threads - 1) // threads
    c = 1.5 * ETA_S if damped else 0.0
    loss = MU * float(np.asarray(setup.gravity_m_s2)[0]) * 0.5 * DT_S if damped else 0.0

    def run():
        kernel((blocks,), (threads,), (inv_mass, kappa, wall_d, v0, np.float64(DT_S), np.int32(grid.n_steps),
                                       np.int32(rows[0]), np.int32(rows[1]), np.float64(c), np.float64(loss),
                                       out, np.int32(chains)))
        cp.cuda.Device().synchronize()
        return out

    first, median, _, _, result = _time(run, repeats)
    peaks = cp.asnumpy(cp.max(result[:, 2, :8], axis=0)).tolist()
    row = {
        "batch": chains, "steps": grid.n_steps, "run_s": median, "compile_s": max(first - median, 0.0),
        "bead_steps_per_s": N_BEADS * chains * grid.n_steps / median, "wall_peak_n": peaks,
    }
    if reference and "wall_peak_n" in reference:
        row["wall_peak_relative_difference_to_jax"] = float(
            np.max(np.abs(np.subtract(peaks, reference["wall_peak_n"])) / np.abs(reference["wall_peak_n"])))
    return row


_CPU_FIT = r"""
import json, sys
sys.path.insert(0, "benchmarks")
from gpu_kernel import item_fit
print("RESULT " + json.dumps(item_fit()))
"""


def item_fit_cpu(cores: int) -> dict:
    """The same fit on `cores` cores of this machine's CPU (JAX on the CPU, the host C++
    kernel, built first and timed apart), in a child process pinned with `taskset`."""
    import os
    import subprocess

    env = dict(os.environ, JAX_PLATFORMS="cpu")
    pin = ["taskset", "-c", ",".join(str(c) for c in range(cores))]
    root = Path(__file__).resolve().parent.parent
    start = time.perf_counter()
    build = subprocess.run([*pin, sys.executable, "-m", "hertzchain", "kernel"], capture_output=True, text=True,
                           env=env, cwd=root, timeout=300)
    row = {"cores": cores, "kernel_build_s": time.perf_counter() - start, "kernel": build.stdout.strip()[-300:]}
    proc = subprocess.run([*pin, sys.executable, "-c", _CPU_FIT], capture_output=True, text=True, env=env,
                          cwd=root, timeout=600)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        return {**row, "error": proc.stderr[-2000:]}
    return {**row, **json.loads(lines[-1][len("RESULT "):])}


def item_fit() -> dict:
    import fitting

    files = fit_bench_traces()
    row = {"n_traces": len(files), "truth": {"eta_s": 2e-6, "mu": 0.19}}
    for label in ("cold", "warm"):
        start = time.perf_counter()
        fitted = fitting.fit(files, ("eta_s", "mu", "C"), progress=False, throw=False)
        row[f"{label}_s"] = time.perf_counter() - start
        row[f"{label}_steps"] = int(fitted.n_steps)
        row[f"{label}_converged"] = bool(fitted.converged)
        row["values"] = {k: float(v) for k, v in dict(fitted.values).items()}
    return row


def save_result(result: dict, out: str, start: float) -> None:
    """Store `result` in the JSON file `out` with its `wall_s`, the seconds since `start` (a
    `time.perf_counter()` reading); called after every item, so that a run cut short keeps
    what it measured."""
    from hertzchain.io.atomic import write_json

    result["wall_s"] = time.perf_counter() - start
    write_json(Path(out), result)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="output JSON file")
    parser.add_argument("--sizes", help="comma-separated chain counts [GPU: 100000; CPU: 256]")
    parser.add_argument("--budget-s", type=float, default=330.0,
                        help="skip the items still to come once this much time has passed [330]")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-fit", action="store_true")
    parser.add_argument("--kinds", default="conservative,damped", help="sweeps to run [conservative,damped]")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)

    start = time.perf_counter()
    device = jax.devices()[0]
    gpu = device.platform == "gpu"
    sizes = [int(float(s)) for s in args.sizes.split(",")] if args.sizes else ([100_000] if gpu else [256])
    result = {"device": str(device), "platform": device.platform, "host": platform.node(),
              "jax": jax.__version__, "case": f"N={N_BEADS}, f64, dt=1us, {STEPS} steps, 3 forces every step; "
              f"damped: eta={ETA_S}, mu={MU}", "items": {}}
    try:
        import cupy

        result["cupy"] = cupy.__version__
    except ImportError as error:
        result["cupy"] = f"unavailable: {error}"

    items = [("cuda_build", item_cuda_build)] if gpu else []
    for size in sizes:
        for damped in [kind == "damped" for kind in args.kinds.split(",")]:
            tag = f"{'damped' if damped else 'conservative'}_{size}"
            items.append((f"jax_{tag}", lambda s=size, d=damped: item_hertzchain(s, d, args.repeats, "jax")))
            items.append((f"hertzchain_{tag}", lambda s=size, d=damped, t=tag: item_hertzchain(
                s, d, args.repeats, "auto", result["items"].get(f"jax_{t}"))))
            items.append((f"kernel_{tag}", lambda s=size, d=damped: item_kernel_alone(s, d, args.repeats)))
            items.append((f"cuda_{tag}", lambda s=size, d=damped, t=tag: item_cuda(
                s, d, args.repeats, result["items"].get(f"jax_{t}"))))
    if not args.skip_fit:
        items.append(("fit", item_fit))
        if gpu:
            items.append(("fit_cpu_2cores", lambda: item_fit_cpu(2)))
    for k, (name, fn) in enumerate(items):
        elapsed = time.perf_counter() - start
        if elapsed > args.budget_s:
            result["items"][name] = {"error": f"skipped: {elapsed:.0f} s of the {args.budget_s:.0f} s budget used"}
            continue
        print(f"[{k + 1}/{len(items)}] {name} ({elapsed:.0f} s elapsed)", flush=True)
        t0 = time.perf_counter()
        try:
            row = fn()
        except Exception as error:  # noqa: BLE001 - every item fails on its own
            row = {"error": f"{type(error).__name__}: {error}", "traceback": traceback.format_exc()[-2000:]}
        row["item_wall_s"] = time.perf_counter() - t0
        result["items"][name] = row
        summary = row.get("bead_steps_per_s") or row.get("warm_s") or row.get("error", "")[:200]
        print(f"    {name}: {summary}", flush=True)
        for size in sizes:  # ratios as soon as both sides are there
            for kind in ("conservative", "damped"):
                plain = result["items"].get(f"cuda_{kind}_{size}", {})
                for impl in ("jax", "hertzchain", "kernel"):
                    ours = result["items"].get(f"{impl}_{kind}_{size}", {})
                    if "bead_steps_per_s" in ours and "bead_steps_per_s" in plain:
                        result.setdefault(f"{impl}_over_cuda", {})[f"{kind}_{size}"] = (
                            ours["bead_steps_per_s"] / plain["bead_steps_per_s"])
        save_result(result, args.out, start)
    print(f"wrote {args.out} ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
