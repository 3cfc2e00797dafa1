"""The batched fast path against the general solver, padding, sharding and energy."""

import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

import hertzchain as hc
from hertzchain.batched import fast_path_reason, solve_batched, stack_setups
from hertzchain.integrate import Recording, solve

N = 10
T_END = 0.8e-3


def _batch(**kwargs):
    base = hc.ChainSetup(N, **kwargs)
    setup, _ = hc.batch_setup(base, striker_velocity_m_s=[0.3, 1.0], wall_youngs_pa=[3e9, 4e11])
    grid = hc.choose_time_grid(setup, t_end_s=T_END, sample_interval_s=2e-6)
    return setup, grid


def _reference(setup, grid, recording):
    return jax.jit(jax.vmap(lambda s: solve(s, grid, recording)))(setup)


CASES = {
    "elastic": {},
    "sensors_preload_viscous": {"sensor_beads": (3, 7), "eta_s": 1e-6, "precompression_n": 5.0},
    "free_end": {"end": "free", "precompression_n": 2.0, "eta_s": 1e-6},
    "viscous": {"eta_s": 2e-6},
}


@pytest.mark.parametrize(
    "case",
    [c if c == "sensors_preload_viscous" else pytest.param(c, marks=pytest.mark.slow) for c in CASES],
)
def test_matches_solve_to_round_off(case):
    setup, grid = _batch(**CASES[case])
    assert fast_path_reason(setup) is None
    recording = Recording((2, 6))
    out = solve_batched(setup, grid, recording)
    ref = _reference(setup, grid, recording)
    assert out.channel_names == ref.channel_names
    for name in out.channel_names:
        scale = float(np.max(np.abs(ref.forces_n[name])))
        assert scale > 1.0 or (name == "wall" and setup.end == "free")  # the pulse got there
        np.testing.assert_allclose(out.forces_n[name], ref.forces_n[name], rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(out.max_force_n, ref.max_force_n, rtol=1e-12)
    energy = np.asarray(ref.initial_energy_j)
    np.testing.assert_allclose(out.initial_energy_j, energy, rtol=1e-13)
    np.testing.assert_allclose(out.energy_error_j, ref.energy_error_j[:, -1], rtol=0, atol=1e-11 * energy.max())
    np.testing.assert_allclose(out.dissipated_j, ref.dissipated_j[:, -1], rtol=0, atol=1e-11 * energy.max())
    # The integrator's own error is small (Verlet at 200 steps per contact).
    assert np.all(np.abs(np.asarray(out.energy_error_j)) < 1e-4 * energy)


def test_padding_does_not_change_results():
    setup, grid = _batch()
    recording = Recording((4,))
    plain = solve_batched(setup, grid, recording)
    padded = solve_batched(setup, grid, recording, pad_to=7)
    assert padded.forces_n["wall"].shape == plain.forces_n["wall"].shape
    np.testing.assert_array_equal(padded.forces_n["wall"], plain.forces_n["wall"])
    np.testing.assert_array_equal(padded.max_force_n, plain.max_force_n)


def test_general_path_for_friction_and_plasticity():
    setups = [hc.ChainSetup(N, mu=0.05, striker_velocity_m_s=v) for v in (0.3, 0.6)]
    setup = stack_setups(setups)
    assert "friction" in fast_path_reason(setup)
    assert "plastic" in fast_path_reason(stack_setups([hc.ChainSetup(N, plasticity=True)]))
    grid = hc.choose_time_grid(setup, t_end_s=T_END, sample_interval_s=2e-6)
    out = solve_batched(setup, grid, Recording((5,)))
    assert out.forces_n["contact_5"].shape == (2, grid.n_samples)
    energy = np.asarray(out.initial_energy_j)
    # Friction dissipates, and the books balance: the general solver's exact ledger.
    assert np.all(np.asarray(out.dissipated_j) > 1e-4 * energy)
    assert np.all(np.abs(np.asarray(out.energy_error_j)) < 1e-4 * energy)


def test_rejects_unbatched_setup_and_record_all():
    grid = hc.choose_time_grid(hc.ChainSetup(N), t_end_s=T_END, sample_interval_s=2e-6)
    with pytest.raises(ValueError, match="batched"):
        solve_batched(hc.ChainSetup(N), grid)
    setup, grid = _batch()
    with pytest.raises(ValueError, match="record_all"):
        solve_batched(setup, grid, Recording((), record_all=True))


_SHARDED = r"""
import json, numpy as np, jax, hertzchain as hc
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
base = hc.ChainSetup(10, eta_s=1e-6)
setup, _ = hc.batch_setup(base, striker_velocity_m_s=[0.3, 0.5, 1.0], wall_youngs_pa=[3e9, 4e11])
grid = hc.choose_time_grid(setup, t_end_s=0.8e-3, sample_interval_s=2e-6)
one = solve_batched(setup, grid, Recording((4,)))
four = solve_batched(setup, grid, Recording((4,)), devices=jax.devices())
diff = max(float(np.max(np.abs(np.asarray(one.forces_n[k]) - np.asarray(four.forces_n[k]))))
           for k in one.channel_names)
print(json.dumps({"devices": len(jax.devices()), "shape": list(four.forces_n["wall"].shape),
                  "diff": diff, "max_diff": float(np.max(np.abs(one.max_force_n - four.max_force_n)))}))
"""


@pytest.mark.slow  # the sweep test runs the same sharding by default
def test_sharded_over_host_devices_matches_one_device():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SHARDED], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["devices"] == 4
    assert result["shape"] == [6, 400]
    assert result["diff"] == 0.0 and result["max_diff"] == 0.0
