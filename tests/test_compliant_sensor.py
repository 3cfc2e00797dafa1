"""Embedded sensors in compliance form: the split-bead mechanics in other coordinates, exact
against the split-bead model, the rigid chain at f0 = inf, and differentiable there."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain import native
from hertzchain.chain import ChainSetup, build_model
from hertzchain.compliant_sensor import CompliantSensors, with_compliant_sensors
from hertzchain.integrate import Recording, solve
from hertzchain.timegrid import TimeGrid, choose_time_grid

N, BEADS, BETA, F0 = 8, (3, 5), 0.11, 85e3
RECORD = Recording(contacts=(2, 3, 4, 5))


# the preloaded chain in the default suite, the bare one with `-m slow` (default-suite time)
@pytest.mark.parametrize("changes", [pytest.param({}, marks=pytest.mark.slow), {"precompression_n": 2.0}],
                         ids=["bare", "preload"])
def test_matches_the_split_bead_model(changes):
    split = ChainSetup(N, striker_velocity_m_s=0.3, sensor_beads=BEADS, sensor_beta=BETA, sensor_f0_hz=F0, **changes)
    grid = choose_time_grid(split, t_end_s=0.5e-3, sample_interval_s=1e-6)
    reference = solve(split, grid, RECORD)
    compliant = solve(ChainSetup(N, striker_velocity_m_s=0.3, **changes), grid, RECORD,
                      compliant_sensors=CompliantSensors.from_f0(BEADS, beta=BETA, f0_hz=F0))
    peak = float(jnp.max(reference.forces_n["wall"]))
    for name in ("contact_2", "contact_3", "contact_4", "contact_5", "wall"):
        np.testing.assert_allclose(compliant.forces_n[name], reference.forces_n[name], atol=1e-11 * peak)
    # The soft sensors change the chain itself: the wall force differs from a rigid chain's.
    rigid = solve(ChainSetup(N, striker_velocity_m_s=0.3, **changes), grid, RECORD)
    assert float(jnp.max(jnp.abs(rigid.forces_n["wall"] - reference.forces_n["wall"]))) > 1e-3 * peak
    # The ledger books the sensors' spring and internal kinetic energy: the same as the split model's.
    np.testing.assert_allclose(compliant.energy_error_j, reference.energy_error_j,
                               atol=1e-6 * float(reference.initial_energy_j))
    assert float(jnp.max(jnp.abs(compliant.energy_error_j))) < 1e-6 * float(compliant.initial_energy_j)


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; the split-bead comparison of this file stays in the default suite
def test_rigid_sensors_are_the_base_chain_and_differentiable_there():
    setup = ChainSetup(N, striker_velocity_m_s=0.2)
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=400)
    base = solve(setup, grid, RECORD)
    rigid = solve(setup, grid, RECORD, compliant_sensors=CompliantSensors(BEADS, BETA, 0.0))
    for name in base.forces_n:
        np.testing.assert_array_equal(rigid.forces_n[name], base.forces_n[name])

    def wall(inv_omega0_sq_s2, beta):
        sensors = CompliantSensors(BEADS, beta, inv_omega0_sq_s2)
        return solve(setup, grid, RECORD, compliant_sensors=sensors).forces_n["wall"]

    # At 1/omega0^2 = 0 (rigid) and at a resolved f0 the derivative matches central differences.
    for inv in (0.0, 1.0 / (2 * np.pi * F0) ** 2):
        d_inv = jax.jacfwd(wall)(inv, BETA)
        step = 2e-3 / (2 * np.pi * F0) ** 2
        central = (wall(inv + step, BETA) - wall(max(inv - step, 0.0), BETA)) / (inv + step - max(inv - step, 0.0))
        assert bool(jnp.all(jnp.isfinite(d_inv)))
        scale = float(jnp.max(jnp.abs(central)))
        assert scale > 0
        np.testing.assert_allclose(d_inv, central, atol=2e-3 * scale)


def test_unresolved_resonance_is_quasi_static_and_close_to_rigid():
    """omega0 dt > 1: the sensor force follows its drive; a 2 MHz sensor barely changes the chain."""
    setup = ChainSetup(N, striker_velocity_m_s=0.3)
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=400)
    base = solve(setup, grid, RECORD)
    stiff = solve(setup, grid, RECORD, compliant_sensors=CompliantSensors.from_f0(BEADS, beta=BETA, f0_hz=2e6))
    peak = float(jnp.max(base.forces_n["wall"]))
    difference = float(jnp.max(jnp.abs(stiff.forces_n["wall"] - base.forces_n["wall"])))
    assert 0 < difference < 5e-3 * peak


def test_bad_sensor_beads_are_refused():
    model = build_model(ChainSetup(N))
    with pytest.raises(ValueError, match="no contact on both sides"):
        with_compliant_sensors(model, (N,), beta=BETA, inv_omega0_sq_s2=1e-12)
    with pytest.raises(ValueError, match="lists a bead twice"):
        with_compliant_sensors(model, (2, 2), beta=BETA, inv_omega0_sq_s2=1e-12)
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=10)
    with pytest.raises(ValueError, match="already splits sensor beads"):
        solve(ChainSetup(N, sensor_beads=(3,)), grid, RECORD, compliant_sensors=CompliantSensors((2,), BETA, 1e-12))


BATCH_CASES = {
    # brass-like beads, a preload, damping and track friction; two sensors side by side (their
    # shared contact shortened by both)
    "brass_preload_damped": (dict(bead_radius_m=5e-3, bead_density_kg_m3=8500.0, bead_youngs_pa=110e9,
                                  precompression_n=2.0, eta_s=2e-7, mu=0.1), (3, 4)),
    # the paper's beads, elastic-plastic contacts (Jackson-Green) that yield, with a dashpot
    "plastic_dashpot": (dict(eta_s=1e-7, dashpot_n_s_m=0.5, plasticity=True, plastic_law="jackson_green",
                             bead_yield_stress_pa=3e8), (2, 5)),
}


@pytest.mark.parametrize("case", [
    # (both with `-m slow`, default-suite time: the plastic case's compiles take half a minute,
    # as the test of its C++ library below; test_batched.py's
    # `test_matches_solve_to_round_off[sensors_preload_viscous]` and `[jackson_green_sensors_preload_viscous]`
    # hold compliant sensors on the batched kernel to `solve` in the default suite)
    pytest.param(case, marks=pytest.mark.slow) for case in sorted(BATCH_CASES)])
def test_batched_kernel_runs_compliant_sensors_as_solve_does(case):
    """`record_batched` with `compliant_sensors` (the brass case on the C++ sensor library, the
    plastic one on the JAX kernel, whose C++ library the slow test below holds to it) against `solve`, chain by
    chain, each chain with its own sensors (f0 85 and 300 kHz): forces to 1e-13 of their
    peaks (measured 3e-15), and without track friction (which acts on each half of a split
    bead) against the split-bead model of the same sensors (another model of the same
    mechanics) to 1e-10; the derivatives in the mass fraction and 1/omega0^2
    equal `solve`'s to 1e-10 of their largest (measured 2e-15)."""
    from hertzchain.batched import kernel_flags, record_batched, stack_setups

    changes, beads = BATCH_CASES[case]
    speeds, betas, f0s = (0.3, 0.6), (0.11, 0.3), (85e3, 300e3)
    setups = [ChainSetup(N, striker_velocity_m_s=v, **changes) for v in speeds]
    grid = choose_time_grid(setups[1], t_end_s=0.25e-3, sample_interval_s=1e-6)
    batch = stack_setups(setups)
    flags = kernel_flags(batch)._replace(ledger=False, sensors=beads)

    kernel = "jax" if changes.get("plasticity") else "auto"

    def batched(beta, inv):
        sensors = CompliantSensors(beads, beta, inv)
        return record_batched(batch, grid, RECORD, flags, compliant_sensors=sensors, kernel=kernel).forces_n

    invs = tuple(1.0 / (2 * np.pi * f) ** 2 for f in f0s)
    out = batched(jnp.asarray(betas), jnp.asarray(invs))
    for k, (setup, beta, f0) in enumerate(zip(setups, betas, f0s)):
        sensors = CompliantSensors.from_f0(beads, beta=beta, f0_hz=f0)
        reference = solve(setup, grid, RECORD, compliant_sensors=sensors).forces_n
        split = solve(ChainSetup(N, striker_velocity_m_s=speeds[k], sensor_beads=beads, sensor_beta=beta,
                                 sensor_f0_hz=f0, **changes), grid, RECORD).forces_n
        for name, trace in reference.items():
            peak = float(jnp.max(jnp.abs(trace)))
            np.testing.assert_allclose(out[name][k], trace, rtol=0, atol=1e-13 * peak)
            if "mu" not in changes:  # (track friction acts on each half of a split bead)
                np.testing.assert_allclose(out[name][k], split[name], rtol=0, atol=1e-10 * peak)
    # the sensors act: the rigid chain's forces differ
    rigid = solve(setups[0], grid, RECORD).forces_n["wall"]
    assert float(jnp.max(jnp.abs(rigid - out["wall"][0]))) > 1e-3 * float(jnp.max(rigid))
    if changes.get("plasticity"):  # and the contacts yield: Hertz's forces differ
        elastic = solve(ChainSetup(N, striker_velocity_m_s=speeds[0], **(changes | {"plasticity": False})), grid,
                        RECORD).forces_n["wall"]
        assert float(jnp.max(jnp.abs(elastic - rigid))) > 1e-2 * float(jnp.max(elastic))

    q = jnp.array([0.2, 3.0])  # beta, 1/omega0^2 in ps^2

    def kernel_side(q):
        return batched(q[0] * jnp.ones(2), q[1] * 1e-12 * jnp.ones(2))["contact_3"]

    def solve_side(q):
        return jnp.stack([solve(s, grid, RECORD, compliant_sensors=CompliantSensors(beads, q[0], q[1] * 1e-12))
                          .forces_n["contact_3"] for s in setups])

    j_kernel, j_solve = jax.jacfwd(kernel_side)(q), jax.jacfwd(solve_side)(q)
    scale = float(jnp.max(jnp.abs(j_solve)))
    assert scale > 0
    np.testing.assert_allclose(j_kernel, j_solve, rtol=0, atol=1e-10 * scale)


KERNEL_CASES = {
    # brass-like beads, a preload, damping and track friction; two sensors side by side
    "preload_damped_friction": (dict(bead_radius_m=5e-3, bead_density_kg_m3=8500.0, bead_youngs_pa=110e9,
                                     precompression_n=2.0, eta_s=2e-7, mu=0.1), (3, 4)),
    # the paper's beads, no damping (the kernel without rates)
    "undamped": (dict(), (2, 5)),
    # damping with a linear dashpot (the sensor library's dashpot runs)
    "dashpot": (dict(eta_s=1e-7, dashpot_n_s_m=0.5), (2, 5)),
    # elastic-plastic contacts (Jackson-Green) that yield: the law's sensor library
    "plastic": (dict(eta_s=1e-7, plasticity=True, plastic_law="jackson_green", bead_yield_stress_pa=3e8), (3, 4)),
    # power-law contacts
    "power_law": (dict(power_law=True, contact_exponent=1.6, exponent_reference_overlap_m=1e-6), (2, 5)),
    # Thornton's elastic-plastic contacts with damping and friction
    "thornton": (dict(eta_s=1e-7, mu=0.1, plasticity=True, plastic_law="thornton", bead_yield_stress_pa=3e8), (3, 4)),
}


@pytest.mark.skipif(not native.available(), reason=f"no native kernel: {native.unavailable_reason()}")
@pytest.mark.parametrize("case", [
    # (every case with `-m slow`: default-suite time on 2 cores; the damped and frictional
    # one's C++ sensor library is held to `solve` by the test above)
    pytest.param(case, marks=pytest.mark.slow) for case in sorted(KERNEL_CASES)])
def test_cpp_kernel_runs_compliant_sensors_as_the_jax_kernel(case):
    """The C++ sensor library of the case's law (`native.run_full(..., sensors=)`, what
    `record_batched` runs on the CPU) against the JAX kernel, 9 chains (three blocks of 4, the
    last one chain and 3 copies of it), each with its own mass fraction and f0 (one
    quasi-static at 30 MHz): forces to 1e-13 of each channel's largest (measured 2e-15), and
    `jacfwd` in the mass fraction and 1/omega0^2 (its custom JVP: the tangents carried
    through the kernel) to 1e-10 (measured 1e-14)."""
    from hertzchain.batched import kernel_flags, record_batched, stack_setups

    changes, beads = KERNEL_CASES[case]
    record = Recording(contacts=(1, 2, 3, 4, 5, 6))
    speeds = np.linspace(0.3, 0.6, 9)
    setups = [ChainSetup(N, striker_velocity_m_s=float(v), **changes) for v in speeds]
    grid = choose_time_grid(setups[-1], t_end_s=0.2e-3, sample_interval_s=1e-6)
    batch = stack_setups(setups)
    flags = kernel_flags(batch)._replace(ledger=False, sensors=beads)
    assert native.kernel_for(flags, None) == native.FusedKernel("full", "host")
    assert flags.law == (changes["plastic_law"] if changes.get("plasticity") else
                         "power_law" if changes.get("power_law") else "hertz")

    def run(beta, inv, kernel):
        sensors = CompliantSensors(beads, beta, inv)
        return record_batched(batch, grid, record, flags, compliant_sensors=sensors, kernel=kernel).forces_n

    betas = jnp.linspace(0.1, 0.5, 9)
    invs = 1.0 / (2 * np.pi * jnp.array([85e3, 120e3, 3e7, 200e3, 300e3, 90e3, 150e3, 250e3, 100e3])) ** 2
    cpp, reference = run(betas, invs, "auto"), run(betas, invs, "jax")
    for name, trace in reference.items():
        np.testing.assert_allclose(cpp[name], trace, rtol=0, atol=1e-13 * float(jnp.max(jnp.abs(trace))))

    def side(q, kernel):  # beta, 1/omega0^2 in ps^2, every chain's
        return run(q[0] * jnp.ones(9), q[1] * 1e-12 * jnp.ones(9), kernel)["contact_4"]

    q = jnp.array([0.2, 3.0])
    j_cpp, j_jax = jax.jacfwd(lambda q: side(q, "auto"))(q), jax.jacfwd(lambda q: side(q, "jax"))(q)
    scale = float(jnp.max(jnp.abs(j_jax)))
    assert scale > 0
    np.testing.assert_allclose(j_cpp, j_jax, rtol=0, atol=1e-10 * scale)


@pytest.mark.skipif(not native.available(), reason=f"no native kernel: {native.unavailable_reason()}")
def test_cpp_kernel_refuses_sensors_it_cannot_run():
    """`native.run_full` with compliant sensors: on the host only (not the one-thread-per-chain
    kernels, here their emulation), and their state (force, rate, drive of each) given."""
    p = {name: jnp.zeros((3, 1)) for name in ("inv_mass", "kappa", "overlap0", "spring", "external")}
    p.update(eta=jnp.zeros(1), friction=jnp.zeros(1), dashpot=jnp.zeros(1))
    x = jnp.zeros((3, 1))
    common = dict(dt_s=1e-7, steps_per_sample=1, n_samples=1, channels=(0,), viscous=False, friction=False,
                  preload=False, springs=False, sensors=(1,))
    if native.thread_unavailable_reason("emulated") is None:
        with pytest.raises(ValueError, match="run on the host kernel"):
            native.run_full(p, x, x, x, backend="emulated", sensor_state=jnp.zeros((3, 1)), **common)
    with pytest.raises(ValueError, match="sensor_state"):
        native.run_full(p, x, x, x, sensor_state=jnp.zeros((2, 1)), **common)


def test_batched_kernel_refuses_inconsistent_compliant_sensors():
    from hertzchain.batched import kernel_flags, record_batched, stack_setups

    batch = stack_setups([ChainSetup(N, striker_velocity_m_s=0.3)])
    grid = TimeGrid(dt_s=2e-7, steps_per_sample=5, n_samples=10)
    sensors = CompliantSensors(BEADS, BETA, 1e-12)
    flags = kernel_flags(batch)._replace(ledger=False)
    with pytest.raises(ValueError, match="flags.sensors"):
        record_batched(batch, grid, RECORD, flags, compliant_sensors=sensors)
    with pytest.raises(ValueError, match="no books"):
        record_batched(batch, grid, RECORD, flags._replace(ledger=True, sensors=BEADS), compliant_sensors=sensors)
