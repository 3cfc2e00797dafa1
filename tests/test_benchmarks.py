"""The benchmark baselines solve the same problem as hertzchain (checked on a short run)."""

import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import hertzchain as hc
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import baselines  # noqa: E402

N, STEPS, DT = 8, 400, 1e-6


@pytest.fixture(scope="module")
def case():
    setup, _ = hc.batch_setup(hc.ChainSetup(N), striker_velocity_m_s=[0.3, 1.0], wall_youngs_pa=[3e9, 4e11])
    model = hc.build_model(hc.ChainSetup(N))
    wall = np.asarray(jax.vmap(lambda s: s.wall_kappa())(setup))
    args = (np.asarray(model.mass_kg), np.asarray(model.kappa), wall,
            np.asarray(setup.striker_velocity_m_s), DT, STEPS, (2, 5))
    grid = hc.choose_time_grid(setup, t_end_s=STEPS * DT, sample_interval_s=DT, dt_s=DT)
    out = solve_batched(setup, grid, Recording((2, 5)))
    reference = np.stack([np.asarray(out.forces_n[k]) for k in out.channel_names], axis=1)  # (B, 3, n)
    return args, np.transpose(reference, (2, 1, 0))


def test_numpy_baselines_match_hertzchain(case):
    args, reference = case
    assert np.max(reference[:, 2]) > 100.0  # the pulse reached the wall
    batch = baselines.numpy_batch(*args)
    np.testing.assert_allclose(batch, reference, rtol=0, atol=1e-9 * np.max(reference))
    single = baselines.numpy_single(args[0], args[1], float(args[2][1]), float(args[3][1]), *args[4:])
    np.testing.assert_allclose(single, reference[:, :, 1], rtol=0, atol=1e-9 * np.max(reference))


@pytest.mark.skipif(not baselines.HAVE_NUMBA, reason="numba not installed")
def test_numba_baselines_match_hertzchain(case):
    args, reference = case
    np.testing.assert_allclose(baselines.numba_batch(*args), reference, rtol=0, atol=1e-9 * np.max(reference))
    single = baselines.numba_single(args[0], args[1], float(args[2][0]), float(args[3][0]), *args[4:])
    np.testing.assert_allclose(single, reference[:, :, 0], rtol=0, atol=1e-9 * np.max(reference))


def test_plain_jax_baseline_matches_hertzchain(case):
    args, reference = case
    # 400 steps in blocks of 30: 13 unrolled blocks and a remainder of 10 steps.
    out = baselines.plain_jax_batch(*args, block=30)
    assert out.shape == reference.shape
    np.testing.assert_allclose(out, reference, rtol=0, atol=1e-9 * np.max(reference))


@pytest.mark.skipif(not baselines.HAVE_NUMBA, reason="numba not installed")
def test_damped_numba_baseline_matches_hertzchain():
    """The damped and frictional Numba kernel (Kuwabara-Kono at every contact, the total
    clipped at 0, track friction) is the physics of hertzchain's damped kernel: the same
    recorded forces on a 70-chain batch (a full block of 64 and a padded one)."""
    speeds = np.linspace(0.2, 1.0, 70)
    setup, _ = hc.batch_setup(hc.ChainSetup(N, eta_s=2e-6, mu=0.19), striker_velocity_m_s=speeds)
    model = hc.build_model(hc.ChainSetup(N))
    wall = np.asarray(jax.vmap(lambda s: s.wall_kappa())(setup))
    grid = hc.choose_time_grid(setup, t_end_s=STEPS * DT, sample_interval_s=DT, dt_s=DT)
    out = solve_batched(setup, grid, Recording((2, 5)), books=False, kernel="jax")
    reference = np.transpose(np.stack([np.asarray(out.forces_n[k]) for k in out.channel_names], axis=1), (2, 1, 0))
    assert np.max(reference[:, 2]) > 100.0  # the pulse reached the wall
    got = baselines.numba_damped_batch(np.asarray(model.mass_kg), np.asarray(model.kappa), wall, speeds, DT, STEPS,
                                       (2, 5), eta_s=2e-6, friction_decel_m_s2=0.19 * 9.81)
    np.testing.assert_allclose(got, reference, rtol=0, atol=1e-9 * np.max(reference))


_CUDA_AS_CPP = r"""
#include <cmath>
using std::sqrt; using std::fabs; using std::fmax;
#define __device__
#define __forceinline__ inline
#define __global__
struct Dim { int x; };
static Dim blockIdx, blockDim, threadIdx;
%s
extern "C" void run_threads(const double* inv_mass, const double* kappa, const double* wall_kappa,
                            const double* v0, double dt, int steps, int r0, int r1, double c,
                            double loss, double* out, int batch) {
  blockDim.x = 1; threadIdx.x = 0;
  for (int j = 0; j < batch; ++j) {
    blockIdx.x = j;
    chain(inv_mass, kappa, wall_kappa, v0, dt, steps, r0, r1, c, loss, out, batch);
  }
}
"""


@pytest.mark.parametrize("damped", [False, True])
def test_gpu_script_cuda_kernel_is_the_same_physics(damped, tmp_path):
    """The plain CUDA kernel of `gpu_kernel.py`, compiled here as C++ with one loop over
    its threads, records the forces of hertzchain's JAX kernel (conservative, and with
    eta = 2 us and mu = 0.19) to round-off: the GPU comparison is like for like."""
    import ctypes
    import shutil
    import subprocess

    import gpu_kernel

    compiler = shutil.which("c++") or shutil.which("g++")
    if compiler is None:
        pytest.skip("no C++ compiler")
    source = tmp_path / "chain.cc"
    source.write_text(_CUDA_AS_CPP % gpu_kernel.CUDA_SOURCE)
    library = tmp_path / "chain.so"
    subprocess.run([compiler, "-O2", "-shared", "-fPIC", f"-DN_BEADS={gpu_kernel.N_BEADS}",
                    f"-DDAMPED={int(damped)}", str(source), "-o", str(library)], check=True)
    run_threads = ctypes.CDLL(str(library)).run_threads
    setup, grid = gpu_kernel._case(16, damped)
    model = hc.build_model(hc.ChainSetup(gpu_kernel.N_BEADS))
    wall = np.asarray(jax.vmap(lambda s: s.wall_kappa())(setup), dtype=float)
    inv_mass, kappa = 1.0 / np.asarray(model.mass_kg), np.asarray(model.kappa)
    v0 = np.asarray(setup.striker_velocity_m_s, dtype=float)
    rows = (gpu_kernel.N_BEADS // 2 - 1, gpu_kernel.N_BEADS // 2)
    out = np.zeros((grid.n_steps, 3, wall.size))
    pointer = ctypes.POINTER(ctypes.c_double)
    c = 1.5 * gpu_kernel.ETA_S if damped else 0.0
    loss = gpu_kernel.MU * float(np.asarray(setup.gravity_m_s2)[0]) * 0.5 * gpu_kernel.DT_S if damped else 0.0
    run_threads(*(a.ctypes.data_as(pointer) for a in (inv_mass, kappa, wall, v0)), ctypes.c_double(grid.dt_s),
                ctypes.c_int(grid.n_steps), ctypes.c_int(rows[0]), ctypes.c_int(rows[1]), ctypes.c_double(c),
                ctypes.c_double(loss), out.ctypes.data_as(pointer), ctypes.c_int(wall.size))
    reference = solve_batched(setup, grid, Recording(rows), books=False, kernel="jax")
    expected = np.transpose(np.stack([np.asarray(reference.forces_n[k]) for k in reference.channel_names], 1),
                            (2, 1, 0))
    assert np.max(expected[:, 2]) > 100.0  # the pulse reached the wall
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-11 * np.max(expected))
