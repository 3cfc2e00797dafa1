"""The fused C++ kernel (`hertzchain.native`) against the JAX kernel and the general solver."""

import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest
from helpers import (
    NEEDS_A_COMPILER,
    TRANSFORMS,
    assert_fit_iteration_equals_the_jax_kernels,
    assert_forces_equal_the_jax_kernels,
    assert_jacfwd_equals_the_jax_kernels,
    assert_transform_is_one_call_equal_to_the_jax_kernel,
    recorded_forces,
    ten_bead_batch,
)

import hertzchain as hc
from hertzchain import native
from hertzchain.batched import kernel_flags, solve_batched
from hertzchain.integrate import Recording, solve_stacked

pytestmark = NEEDS_A_COMPILER


@pytest.fixture(autouse=True)
def _the_kernel_builds():
    assert native.available(), f"a C++ compiler is here but the fused kernel cannot be built: {native.unavailable_reason()}"

CASES = {
    "rigid_and_soft_walls": {},
    "sensors_preload": {"sensor_beads": (3, 7), "precompression_n": 3.0},
    "free_end_preload": {"end": "free", "precompression_n": 2.0},
    "brass_beads": {"bead_radius_m": 2.5e-3, "bead_youngs_pa": 110e9, "bead_poisson": 0.34,
                    "bead_density_kg_m3": 8500.0},
}


@pytest.mark.parametrize("case", list(CASES))
def test_agrees_with_the_jax_kernel_and_solve(case):
    """Forces, maxima and energy books of the C++ kernel equal the JAX kernel's to
    round-off (no fused multiply-adds in the C++ kernel, XLA may use them) and the general
    solver's within its own round-off tolerance."""
    setup, grid = ten_bead_batch(**CASES[case])
    recording = Recording((2, 6))
    fused = solve_batched(setup, grid, recording)
    reference = solve_batched(setup, grid, recording, kernel="jax")
    general = solve_stacked(setup, grid, recording)
    energy = np.asarray(general.initial_energy_j)
    for name in fused.channel_names:
        scale = float(np.max(np.abs(general.forces_n[name])))
        assert scale > 1.0 or (name == "wall" and setup.end == "free")
        np.testing.assert_allclose(fused.forces_n[name], reference.forces_n[name], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(fused.forces_n[name], general.forces_n[name], rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(fused.max_force_n, reference.max_force_n, rtol=1e-12)
    np.testing.assert_allclose(fused.max_force_n, general.max_force_n, rtol=1e-12)
    np.testing.assert_allclose(fused.energy_error_j, general.energy_error_j[:, -1], rtol=0, atol=1e-11 * energy.max())
    assert np.all(np.abs(np.asarray(fused.energy_error_j)) < 1e-4 * energy)  # Verlet's own error is small


def test_chains_do_not_depend_on_their_neighbours_in_a_block():
    """70 chains run as one block of 64, then 6 single chains: each chain's trace is the
    one it gets alone, bit for bit (the lanes of a block never mix)."""
    speeds = np.linspace(0.2, 1.2, 35)
    setup, grid = ten_bead_batch(speeds=speeds)
    together = solve_batched(setup, grid, Recording((4,)))
    for i in (0, 37, 63, 64, 69):
        alone = jax.tree_util.tree_map(lambda leaf, i=i: leaf[i : i + 1], setup)
        one = solve_batched(alone, grid, Recording((4,)))
        for name in together.channel_names:
            np.testing.assert_array_equal(together.forces_n[name][i], one.forces_n[name][0])
        np.testing.assert_array_equal(together.max_force_n[i], one.max_force_n[0])


@pytest.mark.parametrize("chains, checked", [(75, (0, 63, 64, 71, 72, 74)), (8, (0, 3, 4, 7))])
def test_full_kernel_chains_do_not_depend_on_their_neighbours(chains, checked):
    """The full kernel on damped, frictional chains: 75 as a block of 64, one of 8 and a
    block of 4 with 3 chains (its idle lane repeats the last chain); 8 (on two CPUs or more)
    as two blocks of 4, one per thread: each chain's trace is the one it gets alone (a single
    lane), bit for bit."""
    speeds = np.linspace(0.2, 1.2, chains)
    setup, _ = hc.batch_setup(hc.ChainSetup(10, eta_s=2e-6, mu=0.19), striker_velocity_m_s=speeds)
    grid = hc.choose_time_grid(setup, t_end_s=0.5e-3, sample_interval_s=2e-6)
    together = solve_batched(setup, grid, Recording((4,)), books=False)
    for i in checked:
        alone = jax.tree_util.tree_map(lambda leaf, i=i: leaf[i : i + 1], setup)
        one = solve_batched(alone, grid, Recording((4,)), books=False)
        for name in together.channel_names:
            np.testing.assert_array_equal(together.forces_n[name][i], one.forces_n[name][0])


_SHARDED = r"""
import json, numpy as np, jax, hertzchain as hc
from hertzchain import native
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
setup, _ = hc.batch_setup(hc.ChainSetup(10, precompression_n=2.0), striker_velocity_m_s=[0.3, 0.5, 1.0],
                          wall_youngs_pa=[3e9, 4e11])
damped, _ = hc.batch_setup(hc.ChainSetup(10, eta_s=1e-6, mu=0.1, precompression_n=2.0),
                           striker_velocity_m_s=[0.3, 0.5, 1.0], wall_youngs_pa=[3e9, 4e11])
grid = hc.choose_time_grid(setup, t_end_s=0.8e-3, sample_interval_s=2e-6)
result = {"devices": len(jax.devices()), "native": native.available()}
for name, case in (("conservative", setup), ("damped", damped)):
    one = solve_batched(case, grid, Recording((4,)))
    two = solve_batched(case, grid, Recording((4,)), devices=jax.devices())
    result[name] = [max(float(np.max(np.abs(np.asarray(one.forces_n[k]) - np.asarray(two.forces_n[k]))))
                        for k in one.channel_names),
                    float(np.max(np.abs(one.max_force_n - two.max_force_n))),
                    float(np.max(np.abs(one.energy_error_j - two.energy_error_j))),
                    float(np.max(np.abs(one.dissipated_j - two.dissipated_j)))]
print(json.dumps(result))
"""


@pytest.mark.slow  # default-suite time on 2 cores; vmap and jacfwd as one kernel run stay in the default suite
def test_split_over_devices_gives_the_one_device_numbers():
    """The kernels inside `shard_map` over two host devices (one thread each), conservative
    and damped with friction and the books: the same traces, maxima and energies as on one
    device, bit for bit."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SHARDED], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["devices"] == 2 and result["native"]
    assert result["conservative"] == [0.0] * 4 and result["damped"] == [0.0] * 4


_THREADS = r"""
import json, os, sys
if sys.argv[1] == "one":
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # before JAX starts its threads
import numpy as np, hertzchain as hc
from hertzchain import native
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
out = {"native": native.available(), "cpus": len(os.sched_getaffinity(0))}
speeds = list(np.linspace(0.2, 1.0, 15))
for name, kwargs in (("conservative", {}), ("full", {"eta_s": 2e-6, "mu": 0.19})):
    setup, _ = hc.batch_setup(hc.ChainSetup(8, **kwargs), striker_velocity_m_s=speeds,
                              wall_youngs_pa=list(np.geomspace(3e9, 4e11, 10)))
    grid = hc.choose_time_grid(setup, t_end_s=0.4e-3, sample_interval_s=2e-6)
    run = solve_batched(setup, grid, Recording((3,)), books=False)
    out[name] = {k: np.asarray(v).tolist() for k, v in run.forces_n.items()}
print(json.dumps(out))
"""


@pytest.mark.slow  # default-suite time; a chain's numbers do not depend on its block in the default suite
# (`test_chains_do_not_depend_on_their_neighbours_in_a_block`, `test_full_kernel_chains_do_not_depend_on_their_neighbours`)
@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: the blocks run on one thread anyway")
def test_threads_give_the_one_thread_numbers():
    """150 chains (blocks of 64, 8 and single chains) run with the blocks spread over every
    CPU and on one CPU: the same forces bit for bit, conservative and full kernel."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    results = {}
    for mode in ("all", "one"):
        proc = subprocess.run([sys.executable, "-c", _THREADS, mode], capture_output=True, text=True, env=env,
                              timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        results[mode] = json.loads(proc.stdout.strip().splitlines()[-1])
    assert results["all"]["native"] and results["all"]["cpus"] >= 2 and results["one"]["cpus"] == 1
    for kernel in ("conservative", "full"):
        assert results["all"][kernel].keys() == results["one"][kernel].keys()
        for name, trace in results["all"][kernel].items():
            assert np.max(np.abs(trace)) > 1.0
            np.testing.assert_array_equal(np.asarray(trace), np.asarray(results["one"][kernel][name]))


FULL_CASES = {
    "viscous_friction": {"eta_s": 2e-6, "mu": 0.19},
    "viscous": {"eta_s": 2e-6},
    "friction": {"mu": 0.19},
    "sensors_preload_viscous_friction": {"eta_s": 2e-6, "mu": 0.19, "sensor_beads": (3, 7), "precompression_n": 3.0},
    "free_end_preload": {"eta_s": 1e-6, "mu": 0.1, "end": "free", "precompression_n": 2.0},
    "dashpot_friction": {"dashpot_n_s_m": 5.0, "mu": 0.1},
    "dashpot_viscous_sensors": {"dashpot_n_s_m": 5.0, "eta_s": 1e-6, "sensor_beads": (4,), "precompression_n": 1.0},
}


@pytest.mark.parametrize("case", list(FULL_CASES))
def test_damped_and_frictional_forces_agree_with_the_jax_kernel(case):
    """The full C++ kernel (damping, friction; recorded forces only) against the JAX
    kernel: round-off (the sensors' stiff springs amplify it a little)."""
    setup, grid = ten_bead_batch(**FULL_CASES[case])
    assert_forces_equal_the_jax_kernels(setup, grid, books=False)


@pytest.mark.parametrize("dashpot_n_s_m", [0.0, 5.0])
def test_the_dashpot_is_compiled_into_the_runs_that_have_one(dashpot_n_s_m):
    """Damped runs call the full C++ kernel with the dashpot's terms compiled in (FFI
    attribute `dashpot`, the dashpot library's target) exactly when the setup has a
    dashpot: the others keep the kernel without them, whose speed they had
    (`benchmarks/README.md`)."""
    import re

    from hertzchain.batched import kernel_flags, record_batched

    setup, grid = ten_bead_batch(eta_s=1e-6, mu=0.1, dashpot_n_s_m=dashpot_n_s_m)
    flags = kernel_flags(setup)._replace(ledger=False)
    text = jax.jit(lambda s: record_batched(s, grid, Recording((2, 6)), flags).forces_n["wall"]).lower(setup).as_text()
    calls = re.findall(r"custom_call @(hertzchain_chain_full_forward\w*)([^\n]*)", text)
    assert len(calls) == 1
    target, rest = calls[0]
    assert target == native.HOST_LIBRARIES["dashpot" if dashpot_n_s_m > 0 else "chain"].target("full")
    assert f"dashpot = {int(dashpot_n_s_m > 0)} : i64" in rest


def test_a_dashpot_without_the_damped_kernel_is_refused():
    import jax.numpy as jnp

    p = {name: jnp.zeros((2, 1)) for name in ("inv_mass", "kappa", "overlap0", "spring", "external")}
    p.update(eta=jnp.zeros(1), friction=jnp.zeros(1), dashpot=jnp.ones(1))
    x = jnp.zeros((2, 1))
    with pytest.raises(ValueError, match=r"a rate-slot law \(dashpot\) needs viscous=True"):
        native.run_full(p, x, x, x, dt_s=1e-7, steps_per_sample=1, n_samples=1, channels=(0,), viscous=False,
                        friction=False, preload=False, springs=False, rate_law="dashpot")


def assert_books_equal_the_jax_kernels(ours, reference):
    """Largest forces to 1e-12 of themselves and every energy of the books within 1e-12 of
    the impact energy (the sums over the bodies in `batched_step._step`'s order; XLA may fuse)."""
    np.testing.assert_allclose(ours.max_force_n, reference.max_force_n, rtol=1e-12)
    energy = np.asarray(reference.initial_energy_j)
    np.testing.assert_array_equal(ours.initial_energy_j, energy)
    for name in ("kinetic_j", "potential_j", "dissipated_j", "energy_error_j"):
        np.testing.assert_allclose(getattr(ours, name), getattr(reference, name), rtol=0, atol=1e-12 * energy.max())


@pytest.mark.parametrize("case", list(FULL_CASES))
def test_damped_and_frictional_books_agree_with_the_jax_kernel(case):
    """With the books (a sweep's call), damped and frictional chains run the full C++ kernel
    (`native.run_full_books`): forces, largest forces and the energy books equal the JAX
    kernel's to round-off, and the chains lose energy (damping and friction dissipate)."""
    setup, grid = ten_bead_batch(**FULL_CASES[case])
    flags = kernel_flags(setup)
    assert native.kernel_for(flags, None) == native.FusedKernel("full", "host")
    ours, reference = assert_forces_equal_the_jax_kernels(setup, grid, books=True)
    assert_books_equal_the_jax_kernels(ours, reference)
    dissipated = np.asarray(ours.dissipated_j) / np.asarray(ours.initial_energy_j)
    assert np.all(dissipated > 1e-4), dissipated
    assert np.all(np.abs(np.asarray(ours.energy_error_j)) < 1e-3 * np.asarray(ours.initial_energy_j))


def test_books_of_a_mixed_batch_keep_each_chains_own_numbers():
    """70 chains (a block of 64, then a partial block of 8), damped and undamped, with and
    without friction, side by side: the books equal the JAX kernel's, an undamped chain
    without friction dissipates exactly nothing, and each chain's books are those it gets
    alone, bit for bit."""
    speeds = np.linspace(0.2, 1.2, 35)
    base = hc.ChainSetup(10)
    setup, _ = hc.batch_setup(base, striker_velocity_m_s=speeds, eta_s=[0.0, 2e-6])
    friction = np.where(np.arange(70) % 3 == 0, 0.0, 0.19)
    import equinox as eqx
    import jax.numpy as jnp

    setup = eqx.tree_at(lambda s: s.mu, setup, jnp.asarray(friction))
    grid = hc.choose_time_grid(setup, t_end_s=0.8e-3, sample_interval_s=2e-6)
    ours, reference = assert_forces_equal_the_jax_kernels(setup, grid, books=True)
    assert_books_equal_the_jax_kernels(ours, reference)
    eta = np.asarray(setup.eta_s)
    idle = (eta == 0.0) & (friction == 0.0)
    assert idle.any() and np.all(np.asarray(ours.dissipated_j)[idle] == 0.0)
    for i in (0, 5, 63, 64, 69):
        alone = jax.tree_util.tree_map(lambda leaf, i=i: leaf[i:i + 1], setup)
        one = solve_batched(alone, grid, Recording((4,)))
        np.testing.assert_array_equal(ours.max_force_n[i], one.max_force_n[0])
        np.testing.assert_array_equal(ours.dissipated_j[i], one.dissipated_j[0])
        np.testing.assert_array_equal(ours.kinetic_j[i], one.kinetic_j[0])


# The default suite keeps the dashpot case (the same five directions, and the dashpot's, through
# the dashpot library); the main library's tangents in eta, mu and C stay held to the JAX
# kernel's by `test_fit_residuals_and_jacobian_equal_the_jax_kernels` and
# `tests/test_fit_model.py`. The other two run with `-m slow` (suite time).
# every case with `-m slow` (default-suite time on 2 cores): the C++ kernel's tangents are held
# to `jax.jacfwd` through the JAX kernel in the default suite by
# `test_friction_derivatives_with_and_without_loss_equal_the_jax_kernels` (damping, friction,
# impact speed) and `test_fit_residuals_and_jacobian_equal_the_jax_kernels` (a fit's Jacobian)
@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) for c in
                                  ("viscous_friction", "viscous_friction_dashpot", "sensors_preload_viscous_friction")])
def test_forward_mode_derivatives_equal_jacfwd_through_the_jax_kernel(case):
    """`jax.jacfwd` through `record_batched` on the C++ kernel (its own tangents, five or six
    directions in one run: damping, friction, impact speed, preload, bead modulus, dashpot)
    equals `jax.jacfwd` through the JAX kernel to round-off, and `jax.jvp` and
    `jax.linearize` along one direction equal the Jacobian's column; values equal too."""
    import jax.numpy as jnp

    q = jnp.asarray([2e-6, 0.19, 1.0, 1.0, 1.0] + ([3.0] if case.endswith("_dashpot") else []))
    case = case.removesuffix("_dashpot")
    kwargs = {k: v for k, v in FULL_CASES[case].items() if k not in ("eta_s", "mu", "precompression_n")}
    base, grid = ten_bead_batch(speeds=(0.3, 1.0, 0.5), precompression_n=1.0, **kwargs)
    jac = np.asarray(jax.jit(jax.jacfwd(lambda q: recorded_forces(base, grid, q, "auto")))(q))
    reference = np.asarray(jax.jit(jax.jacfwd(lambda q: recorded_forces(base, grid, q, "jax")))(q))
    for i in range(q.size):
        scale = np.max(np.abs(reference[..., i]))
        assert scale > 0.0
        # friction's derivative crosses stick-slip kinks: 1e-10 (1e-11 measured)
        np.testing.assert_allclose(jac[..., i], reference[..., i], rtol=0, atol=1e-10 * scale)
    direction = jnp.zeros(q.size).at[1].set(1.0)
    value, tangent = jax.jvp(lambda q: recorded_forces(base, grid, q, "auto"), (q,), (direction,))
    np.testing.assert_allclose(np.asarray(tangent), jac[..., 1], rtol=0, atol=1e-12 * np.max(np.abs(jac[..., 1])))
    _, linear = jax.linearize(lambda q: recorded_forces(base, grid, q, "auto"), q)
    np.testing.assert_array_equal(np.asarray(linear(direction)), np.asarray(tangent))
    expected = np.asarray(recorded_forces(base, grid, q, "jax"))
    np.testing.assert_allclose(np.asarray(value), expected, rtol=0, atol=2e-12 * np.max(np.abs(expected)))


def test_friction_derivatives_with_and_without_loss_equal_the_jax_kernels():
    """The friction kick's tangent (`chain_laws.h`'s `Kick` on dual numbers) in one batch of
    chains with friction and chains with friction switched on but mu = 0 (beads at rest
    ahead of the wave: the loss above the speed, or a kept speed of exactly 0): `jax.jacfwd`
    in damping, friction and impact speed equals it through the JAX kernel, and mu's
    direction moves the mu = 0 chains not at all. (At a velocity of exactly 0 with no loss,
    sign(0) = 0 makes the slope 0, as the dual numbers' `CopySign` keeps it; the tangents
    reaching such a bead are 0 here, so that case is not observable in a chain's traces.)"""
    import equinox as eqx
    import jax.numpy as jnp

    from hertzchain.batched import record_batched

    base, grid = ten_bead_batch(speeds=(0.3, 1.0, 0.5, 0.8), eta_s=1e-6)
    flags = kernel_flags(base, switched_on=("viscous", "friction"))._replace(ledger=False)
    chains = base.eta_s.shape[0]  # 4 speeds x 2 walls
    mu = jnp.asarray(np.resize([0.0, 0.19, 0.0, 0.1, 0.19], chains))

    def traced(q, kernel):
        setup = eqx.tree_at(lambda s: (s.eta_s, s.mu, s.striker_velocity_m_s), base,
                            (q[0] * jnp.ones(chains), q[1] * mu, q[2] * base.striker_velocity_m_s))
        out = record_batched(setup, grid, Recording((2, 6)), flags, kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    jac = assert_jacfwd_equals_the_jax_kernels(traced, jnp.asarray([1e-6, 1.0, 1.0]))
    np.testing.assert_array_equal(jac[:, np.asarray(mu) == 0.0, :, 1], 0.0)  # mu = 0 moves nothing


@pytest.mark.slow  # default-suite time; the power-law library's values against `solve`: test_batched.py's
# `test_matches_solve_to_round_off[power_law_free_end]`
def test_power_law_runs_on_the_full_kernel_equal_to_the_jax_kernel():
    """Power-law contacts (n = 1.6) run the full C++ kernel's power-law library: a damped,
    frictional sweep with the books and a conservative run without them equal the JAX
    kernel's to round-off, and `jax.jacfwd` through `record_batched` in damping, friction, the
    exponent, the reference overlap and the impact speed (the law's own tangents through the
    loop) equals `jax.jacfwd` through the JAX kernel."""
    import equinox as eqx
    import jax.numpy as jnp

    from hertzchain.batched import record_batched

    base, grid = ten_bead_batch(speeds=(0.3, 1.0, 0.5), contact_exponent=1.6, eta_s=1e-6, mu=0.1,
                        sensor_beads=(4,), precompression_n=1.0)
    flags = kernel_flags(base)
    assert native.kernel_for(flags, None) == native.FusedKernel("full", "host")
    ours, reference = assert_forces_equal_the_jax_kernels(base, grid, books=True)
    assert_books_equal_the_jax_kernels(ours, reference)
    elastic, _ = ten_bead_batch(contact_exponent=1.4)
    assert native.kernel_for(kernel_flags(elastic), None) == native.FusedKernel("full", "host")
    assert_books_equal_the_jax_kernels(*assert_forces_equal_the_jax_kernels(elastic, grid, books=True))
    assert_forces_equal_the_jax_kernels(elastic, grid, books=False)

    def traced(q, kernel):
        ones = jnp.ones(base.eta_s.shape)
        setup = eqx.tree_at(
            lambda s: (s.eta_s, s.mu, s.contact_exponent, s.exponent_reference_overlap_m, s.striker_velocity_m_s),
            base, (q[0] * ones, q[1] * ones, q[2] * ones, q[3] * ones, q[4] * base.striker_velocity_m_s))
        out = record_batched(setup, grid, Recording((2, 6)), flags._replace(ledger=False), kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([1e-6, 0.1, 1.6, 2e-6, 1.0])
    jacobian = jax.jit(jax.jacfwd(lambda q: traced(q, "auto")))
    assert jacobian.lower(q).as_text().count(f"custom_call @{native.HOST_LIBRARIES['power_law'].target('tangent')}") == 1
    jac = np.asarray(jacobian(q))
    expected = np.asarray(jax.jit(jax.jacfwd(lambda q: traced(q, "jax")))(q))
    for i in range(q.size):
        scale = np.max(np.abs(expected[..., i]))
        assert scale > 0.0
        np.testing.assert_allclose(jac[..., i], expected[..., i], rtol=0, atol=1e-10 * scale)


# In the slow suite (about 12 s each beyond the laws' builds, with the default suite at its
# 10 minutes): the default suite holds both laws' C++ forces to `contact` in
# `test_batched.py::test_every_kernel_applies_the_laws_of_contact`, Jackson-Green's C++
# forces and books to `solve` in `test_batched.py::test_matches_solve_to_round_off`, and a
# fit's Jacobian through yielding Jackson-Green contacts on the C++ kernel to `solve`'s in
# `test_fit_model.py::test_batched_kernel_and_solve_give_the_same_model_and_jacobian`.
@pytest.mark.slow
@pytest.mark.parametrize("law", ["thornton", "jackson_green"])
def test_elastic_plastic_contacts_run_on_the_full_kernel_equal_to_the_jax_kernel(law):
    """Elastic-plastic contacts (`contact.thornton_contact`, `contact.jackson_green_contact`;
    sigma_Y = 1.2 GPa, so that the faster strikers yield the contacts) run the full C++
    kernel's library of their law, every contact's largest overlap carried through the steps:
    an undamped sweep with the books, forces, largest forces and energies (the plastic work
    included) equal to the JAX kernel's to round-off; and `jax.jacfwd` through
    `record_batched` (damped, frictional, preloaded: its forces too) in damping, the
    yield stress, the impact speed and the beads' Poisson ratio (the unloading curves' own
    tangents, carried from the peaks) equal to `jax.jacfwd` through the JAX kernel."""
    import equinox as eqx
    import jax.numpy as jnp

    from hertzchain.batched import record_batched

    plastic = dict(plasticity=True, plastic_law=law, bead_yield_stress_pa=1.2e9)
    elastic, _ = ten_bead_batch(speeds=(0.3, 3.0, 1.5), **plastic)
    grid = hc.choose_time_grid(elastic, t_end_s=0.4e-3, sample_interval_s=2e-6)  # the first contacts yield
    assert native.kernel_for(kernel_flags(elastic), None) == native.FusedKernel("full", "host")
    ours, reference = assert_forces_equal_the_jax_kernels(elastic, grid, books=True)
    assert_books_equal_the_jax_kernels(ours, reference)
    spent = np.asarray(ours.dissipated_j) / np.asarray(ours.initial_energy_j)  # plastic work alone here
    assert np.all(spent[2:] > 0.5) and np.all(spent >= 0.0), spent  # the 3 m/s strikers yield the contacts

    base, _ = ten_bead_batch(speeds=(0.3, 3.0, 1.5), eta_s=1e-6, mu=0.1, precompression_n=1.0, **plastic)
    flags = kernel_flags(base)

    def traced(q, kernel):
        ones = jnp.ones(base.eta_s.shape)
        setup = eqx.tree_at(
            lambda s: (s.eta_s, s.bead_yield_stress_pa, s.striker_velocity_m_s, s.bead_poisson), base,
            (q[0] * ones, q[1] * ones, q[2] * base.striker_velocity_m_s, q[3] * base.bead_poisson))
        out = record_batched(setup, grid, Recording((2, 6)), flags._replace(ledger=False), kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([1e-6, 1.2e9, 1.0, 1.0])
    def evaluation(kernel):  # a fit's evaluation: the forces and their Jacobian
        return jax.jit(lambda q: (traced(q, kernel), jax.jacfwd(lambda q: traced(q, kernel))(q)))

    fused = evaluation("auto")
    assert fused.lower(q).as_text().count(f"custom_call @{native.HOST_LIBRARIES[law].target('tangent')}") == 1
    (forces, jac), (expected_forces, expected) = fused(q), evaluation("jax")(q)
    np.testing.assert_allclose(forces, expected_forces, rtol=0, atol=2e-12 * np.max(np.abs(expected_forces)))
    jac, expected = np.asarray(jac), np.asarray(expected)
    for i in range(q.size):
        scale = np.max(np.abs(expected[..., i]))
        assert scale > 0.0
        np.testing.assert_allclose(jac[..., i], expected[..., i], rtol=0, atol=1e-11 * scale)


# `jacfwd` alone is `test_forward_mode_derivatives_equal_jacfwd_through_the_jax_kernel`'s
# (its values; the one call is held by the compositions here), and `vmap` of `vmap` of
# `jacfwd` composes the rules the others check one level deep: both in the slow suite, and so
# is `vmap` of `jacfwd` (default-suite time: `jacfwd` of `vmap` keeps the composition).
@pytest.mark.parametrize("transform", [pytest.param(t, marks=pytest.mark.slow)
                                       if t in ("jacfwd", "vmap_of_jacfwd", "vmap_of_vmap_of_jacfwd") else t
                                       for t in TRANSFORMS])
def test_vmap_and_jacfwd_are_one_kernel_run_equal_to_the_jax_kernel(transform):
    """A vmapped batch of parameter vectors (the case of a batch of fits), `jacfwd`, and
    their compositions: one run of the C++ kernel each (the mapped chains join its batch,
    the directions its direction axis), values and derivatives those of the JAX kernel."""
    assert_transform_is_one_call_equal_to_the_jax_kernel(
        transform, lambda t: "hertzchain_chain_full_forward" if t == "vmap" else "hertzchain_chain_full_tangent")


def test_conservative_kernel_under_vmap_is_one_run_bit_for_bit():
    """The conservative kernel (`native.run`) mapped over two initial states (the second
    with halved velocities): one kernel run of both sets' chains, each set's final state
    and traces those of its own run, bit for bit (the lanes never mix)."""
    import jax.numpy as jnp

    from hertzchain.batched import _initial, _Layout, kernel_flags, kernel_params

    setup, grid = ten_bead_batch(speeds=(0.3, 0.6, 1.0))
    flags = kernel_flags(setup)._replace(ledger=True)
    p = kernel_params(setup)
    layout = _Layout(p["mass"].shape[0])
    state, _, _ = _initial(p, flags, layout, grid.dt_s)
    rows = layout.bodies + 1  # x, then u = v + (dt/2) a, then the books
    states = jnp.stack([state, state.at[rows : 2 * rows].multiply(0.5)])
    kwargs = dict(dt_s=grid.dt_s, steps_per_sample=grid.steps_per_sample, n_samples=grid.n_samples,
                  channels=(2, 6), preload=False, springs=False, books=True)
    mapped = jax.jit(jax.vmap(lambda s: native.run(p, s, **kwargs)))
    hlo = mapped.lower(states).as_text()
    assert hlo.count("hertzchain_chain_forward") == 1 and "while" not in hlo
    traces, final = mapped(states)
    for k in range(2):
        one_traces, one_final = jax.jit(lambda s: native.run(p, s, **kwargs))(states[k])
        np.testing.assert_array_equal(final[k], one_final)
        for trace, one in zip(traces, one_traces):
            np.testing.assert_array_equal(trace[k], one)
    assert not np.array_equal(traces[0][0], traces[0][1])


def test_unknown_kernel_is_refused():
    setup, grid = ten_bead_batch()
    with pytest.raises(ValueError, match="kernel must be"):
        solve_batched(setup, grid, Recording((4,)), kernel="c++")


_SWITCHED_OFF = r"""
import json, numpy as np, hertzchain as hc
from hertzchain import native
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
setup, _ = hc.batch_setup(hc.ChainSetup(10), striker_velocity_m_s=[0.3, 1.0], wall_youngs_pa=[3e9, 4e11])
grid = hc.choose_time_grid(setup, t_end_s=0.8e-3, sample_interval_s=2e-6)
out = solve_batched(setup, grid, Recording((4,)))
print(json.dumps({"reason": native.unavailable_reason(), "wall": np.asarray(out.forces_n["wall"]).tolist()}))
"""


def test_switched_off_runs_the_jax_kernel(tmp_path):
    """HERTZCHAIN_NATIVE=0: the kernel is not loaded, says why, and the JAX kernel runs."""
    env = dict(os.environ, HERTZCHAIN_NATIVE="0", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SWITCHED_OFF], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert "HERTZCHAIN_NATIVE=0" in result["reason"]
    setup, grid = ten_bead_batch()
    reference = solve_batched(setup, grid, Recording((4,)), kernel="jax")
    np.testing.assert_array_equal(np.asarray(result["wall"]), reference.forces_n["wall"])


@pytest.mark.skipif(native.build._cxx() is None, reason="no C++ compiler")
def test_builds_without_vector_masks_may_speculate_floating_point_operations(monkeypatch):
    """AVX2 builds get -fno-trapping-math (their tangent loops stay vectorised), AVX-512
    builds do not; both keep IEEE arithmetic without contraction."""
    monkeypatch.setenv(native.ARCH_VARIABLE, "haswell")
    assert "-fno-trapping-math" in native.build._flags()
    monkeypatch.setenv(native.ARCH_VARIABLE, "skylake-avx512")
    assert "-fno-trapping-math" not in native.build._flags()
    for arch in ("haswell", "skylake-avx512"):
        monkeypatch.setenv(native.ARCH_VARIABLE, arch)
        assert "-ffp-contract=off" in native.build._flags() and not any("fast-math" in f for f in native.build._flags())


_REUSE = r"""
import ctypes, json, resource
from hertzchain import native
tuned = native.host._keep_freed_buffers()
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
faults = []
for _ in range(2):  # a 20 MB result buffer, written whole and freed, twice
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    buffer = libc.malloc(20 << 20)
    ctypes.memset(buffer, 1, 20 << 20)
    libc.free(buffer)
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(json.dumps({"tuned": tuned, "faults": faults}))
"""


@pytest.mark.skipif(sys.platform != "linux", reason="glibc's malloc options")
@pytest.mark.parametrize("setting", ["1", "0"])
def test_freed_result_buffers_are_reused_not_faulted_in_again(setting):
    """With the malloc tuning a second 20 MB buffer reuses the first one's pages (a few page
    faults, against 5120 pages of 4 kB), and without it (HERTZCHAIN_MALLOC_TUNING=0) glibc
    maps it afresh: the tuning is what makes the difference."""
    env = dict(os.environ, HERTZCHAIN_MALLOC_TUNING=setting)
    proc = subprocess.run([sys.executable, "-c", _REUSE], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["tuned"] is (setting == "1")
    assert result["faults"][0] > 2000  # the first buffer is new memory either way
    if setting == "1":
        assert result["faults"][1] < 100
    else:
        assert result["faults"][1] > 2000


def test_failed_build_names_the_compiler_error(tmp_path):
    """A source that does not compile: the build raises with the compiler's message and
    leaves no library behind (written whole or not at all)."""
    broken = tmp_path / "chain_kernel.cc"
    broken.write_text("this is not C++\n")
    target = tmp_path / "cache" / "kernel.so"
    with pytest.raises(RuntimeError, match="compiling chain_kernel.cc failed"):
        native.build._build(target, source=broken)
    assert not target.exists() and list(target.parent.iterdir()) == []


def test_a_kernel_that_cannot_be_built_is_announced_once_with_its_reason(tmp_path, monkeypatch, capsys):
    """A failed build (or no compiler): the JAX kernel runs, and stderr says so once a process
    with the first line of the reason; switched off on purpose (HERTZCHAIN_NATIVE=0), nothing
    is said."""
    def no_compiler(*args, **kwargs):
        raise RuntimeError("no C++ compiler found (set CXX, or install g++)\nmore detail")

    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
    monkeypatch.setattr(native.build, "_build", no_compiler)
    monkeypatch.setattr(native.registry, "_FAILED", {})
    monkeypatch.setattr(native.host, "_load_main", native.host._load_main.__wrapped__)
    load = native.host._load.__wrapped__  # the uncached build-and-load (the cache says it once a process)
    monkeypatch.delenv("HERTZCHAIN_NATIVE", raising=False)
    for _ in range(2):
        assert load() == "no C++ compiler found (set CXX, or install g++)\nmore detail"
    said = capsys.readouterr().err
    assert said.count("the fused C++ kernel cannot be used (no C++ compiler found (set CXX, or install g++))") == 1
    assert "the JAX kernel runs instead" in said and "more detail" not in said
    monkeypatch.setenv("HERTZCHAIN_NATIVE", "0")
    assert load() == "switched off (HERTZCHAIN_NATIVE=0)"
    assert capsys.readouterr().err == ""


def test_fit_residuals_and_jacobian_equal_the_jax_kernels(monkeypatch):
    """A fit iteration on the C++ kernel and its tangents equals the JAX kernel's."""
    assert_fit_iteration_equals_the_jax_kernels(monkeypatch)
