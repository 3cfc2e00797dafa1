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
