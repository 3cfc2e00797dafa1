"""The batched fast path against the general solver, padding, sharding and energy."""

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import rerun_at_the_default_xla_level

import hertzchain as hc
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording, solve_stacked

N = 10
T_END = 0.8e-3


def _batch(**kwargs):
    base = hc.ChainSetup(N, **kwargs)
    setup, _ = hc.batch_setup(base, striker_velocity_m_s=[0.3, 1.0], wall_youngs_pa=[3e9, 4e11])
    grid = hc.choose_time_grid(setup, t_end_s=T_END, sample_interval_s=2e-6)
    return setup, grid


def _reference(setup, grid, recording):
    return solve_stacked(setup, grid, recording)


CASES = {
    "elastic": {},
    "sensors_preload_viscous": {"sensor_beads": (3, 7), "eta_s": 1e-6, "precompression_n": 5.0},
    "free_end": {"end": "free", "precompression_n": 2.0, "eta_s": 1e-6},
    "viscous": {"eta_s": 2e-6},
    "friction": {"mu": 0.05},
    "friction_viscous_preload": {"mu": 0.2, "eta_s": 1e-6, "precompression_n": 3.0, "sensor_beads": (4,)},
    # yield stresses low enough that the 1 m/s chain yields (its contacts peak near 300 N)
    "thornton": {"plasticity": True, "bead_yield_stress_pa": 1.0e9},
    "jackson_green_sensors_preload_viscous": {"plasticity": True, "plastic_law": "jackson_green",
                                              "bead_yield_stress_pa": 0.4e9, "sensor_beads": (3,),
                                              "precompression_n": 2.0, "eta_s": 1e-6},
    "power_law_free_end": {"contact_exponent": 1.7, "end": "free", "precompression_n": 2.0},
    "dashpot_friction": {"dashpot_n_s_m": 4.0, "mu": 0.1},
    "jackson_green_dashpot": {"plasticity": True, "plastic_law": "jackson_green", "bead_yield_stress_pa": 0.4e9,
                              "dashpot_n_s_m": 4.0, "eta_s": 1e-6},
}
QUICK = ("sensors_preload_viscous", "friction_viscous_preload", "jackson_green_sensors_preload_viscous",
         "power_law_free_end", "dashpot_friction", "jackson_green_dashpot")


@pytest.mark.parametrize("case", [c if c in QUICK else pytest.param(c, marks=pytest.mark.slow) for c in CASES])
def test_matches_solve_to_round_off(case):
    """Every physics of `ChainSetup` on the batched kernel: the general solver's forces,
    maxima and energy books to round-off (plastic contacts dissipate, and the books say so)."""
    setup, grid = _batch(**CASES[case])
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
    if setup.plasticity:  # the faster chain yields: work lost to plastic flow is on the books
        assert float(ref.dissipated_j[1, -1]) > 1e-3 * energy[1]


def test_padding_does_not_change_results():
    setup, grid = _batch()
    recording = Recording((4,))
    plain = solve_batched(setup, grid, recording)
    padded = solve_batched(setup, grid, recording, pad_to=7)
    assert padded.forces_n["wall"].shape == plain.forces_n["wall"].shape
    np.testing.assert_array_equal(padded.forces_n["wall"], plain.forces_n["wall"])
    np.testing.assert_array_equal(padded.max_force_n, plain.max_force_n)


@pytest.mark.parametrize("case", ["sensors_preload_viscous", "friction_viscous_preload"])
def test_parameters_shared_by_the_batch_give_the_same_results(case):
    """A sweep over striker speeds and walls shares the bodies' masses: the kernel reads
    them as one column. The results are those of per-chain copies, bit for bit
    (same numbers through the same arithmetic), the books included (the sharded
    tests run shared columns on several devices)."""
    from hertzchain import batched

    setup, grid = _batch(**CASES[case])
    params = batched.kernel_params(setup)
    shared = batched.share_uniform(params)
    assert shared["inv_mass"].shape[-1] == 1 and shared["mass"].shape[-1] == 1
    assert shared["kappa"].shape[-1] == 4 and shared["v0"].shape[-1] == 4  # the walls differ
    names, rows, user = batched._plan(setup, Recording((2, 6)))
    flags = batched.kernel_flags(setup)
    run = lambda p: batched._solve_fast(p, 4, flags, grid, rows, names, user, 20, None)  # noqa: E731
    full, reduced = run(params), run(shared)
    for name in names:
        np.testing.assert_array_equal(reduced.forces_n[name], full.forces_n[name])
    np.testing.assert_array_equal(reduced.max_force_n, full.max_force_n)
    np.testing.assert_array_equal(reduced.energy_error_j, full.energy_error_j)


def test_friction_dissipates_what_the_track_takes():
    """Friction alone on the fast path: energy leaves the chain (the books balance to the
    integrator's error) and the pulse reaching the wall is weaker than without it."""
    setup, grid = _batch(mu=0.3)
    out = solve_batched(setup, grid, Recording((5,)))
    energy = np.asarray(out.initial_energy_j)
    assert np.all(np.asarray(out.dissipated_j) > 1e-4 * energy)
    assert np.all(np.abs(np.asarray(out.energy_error_j)) < 1e-4 * energy)
    frictionless = solve_batched(_batch()[0], grid, Recording((5,)))
    assert np.all(np.asarray(out.max_force_n)[:, -1] < np.asarray(frictionless.max_force_n)[:, -1])


def test_rejects_unbatched_setup_and_record_all():
    grid = hc.choose_time_grid(hc.ChainSetup(N), t_end_s=T_END, sample_interval_s=2e-6)
    with pytest.raises(ValueError, match="batched"):
        solve_batched(hc.ChainSetup(N), grid)
    setup, grid = _batch()
    with pytest.raises(ValueError, match="record_all"):
        solve_batched(setup, grid, Recording((), record_all=True))


_SHARDED = r"""
import json, sys, numpy as np, jax, hertzchain as hc
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording
base = hc.ChainSetup(10, **json.loads(sys.argv[1]))
setup, _ = hc.batch_setup(base, striker_velocity_m_s=[0.3, 0.5, 1.0], wall_youngs_pa=[3e9, 4e11])
grid = hc.choose_time_grid(setup, t_end_s=0.8e-3, sample_interval_s=2e-6)
one = solve_batched(setup, grid, Recording((4,)))
four = solve_batched(setup, grid, Recording((4,)), devices=jax.devices())
diff = max(float(np.max(np.abs(np.asarray(one.forces_n[k]) - np.asarray(four.forces_n[k]))))
           for k in one.channel_names)
print(json.dumps({"devices": len(jax.devices()), "shape": list(four.forces_n["wall"].shape),
                  "diff": diff, "max_diff": float(np.max(np.abs(one.max_force_n - four.max_force_n))),
                  "dissipated_diff": float(np.max(np.abs(one.dissipated_j - four.dissipated_j))),
                  "scale": float(np.max(one.max_force_n)), "energy": float(np.max(one.initial_energy_j))}))
"""


@pytest.mark.slow  # the sweep test runs the same sharding by default
@pytest.mark.parametrize("physics", [{"eta_s": 1e-6},
                                     {"plasticity": True, "plastic_law": "jackson_green", "bead_yield_stress_pa": 0.4e9}])
def test_sharded_over_host_devices_matches_one_device(physics):
    """Four host devices (padded batch, parameters shared by the batch sent to every device,
    plastic contacts' largest overlaps in the state): the one device's numbers, bit for bit
    for Hertz contacts. Jackson-Green's law takes powers and exponentials, whose vectorised
    and scalar code in XLA's loops differ by an ulp, and a chain's place in those loops
    changes with the split: round-off there (2e-13 N of 300 N measured)."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SHARDED, json.dumps(physics)], capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["devices"] == 4
    assert result["shape"] == [6, 400]
    if "plasticity" not in physics:
        assert result["diff"] == 0.0 and result["max_diff"] == 0.0 and result["dissipated_diff"] == 0.0
    assert max(result["diff"], result["max_diff"]) <= 1e-14 * result["scale"]
    assert result["dissipated_diff"] <= 1e-14 * result["energy"]


# the elastic, Thornton and Jackson-Green-with-dashpot cases in the default suite, the others
# with `-m slow` (default-suite time: `test_matches_solve_to_round_off` holds every quick case's
# whole run to `solve`)
FORCE_LAW_CASES = ("elastic", "thornton", "jackson_green_dashpot")


@pytest.mark.parametrize("case", [c if c in FORCE_LAW_CASES else pytest.param(c, marks=pytest.mark.slow)
                                  for c in CASES])
def test_fast_path_uses_the_force_laws_of_solve(case):
    """The fast path's contact forces, body forces and energies, evaluated on random
    compressed and separated states (plastic contacts: loading and unloading below larger
    overlaps reached before), are those of `forces.chain_forces` (same contact-law
    functions of `contact`, so the forces are bit-identical)."""
    from hertzchain import batched, batched_step, forces

    setup, _ = _batch(**CASES[case])
    flags = batched.kernel_flags(setup)
    params = batched.share_uniform(batched.kernel_params(setup))
    models = [hc.build_model(jax.tree_util.tree_map(lambda leaf, i=i: leaf[i], setup)) for i in range(4)]
    n_bodies = models[0].mass_kg.shape[0]
    rng = np.random.default_rng(3)
    x = rng.normal(scale=2e-6, size=(n_bodies, 4))  # about half the contacts compressed
    v = rng.normal(scale=0.3, size=(n_bodies, 4))
    wall = np.zeros((1, 4))
    xw, vw = np.concatenate([x, wall]), np.concatenate([v, wall])
    overlap = np.asarray(batched_step._overlaps(params, flags, xw))
    peak = np.where(rng.random(overlap.shape) < 0.5, overlap, np.maximum(overlap, 0.0) + 3e-6 * rng.random(overlap.shape))
    peak = peak if flags.plastic else None
    total, elastic = batched_step._contact_forces(params, flags, xw, vw, peak=peak)
    body = batched_step._body_force(total, params["external"])[:n_bodies]
    kinetic, potential, plastic = batched_step._energy(params, flags, xw, vw, peak)
    for i, model in enumerate(models):
        max_overlap = None if peak is None else jnp.asarray(peak[:, i])
        ref = forces.chain_forces(model, jnp.asarray(x[:, i]), jnp.asarray(v[:, i]), max_overlap)
        assert np.sum(np.asarray(ref.contact_total_n) > 0) >= 2  # some contacts are loaded
        # Bit for bit, except where the kernel's parameters are transcendental functions of the
        # setup (Jackson-Green's yield forces): computed under `jit` and `vmap` there, an ulp
        # off the eager ones here.
        same = np.testing.assert_array_equal if flags.law != "jackson_green" else (
            lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-14, atol=0))
        same(total[:-1, i], ref.contact_total_n)
        same(total[-1, i], ref.wall_total_n)
        same(elastic[:-1, i], ref.contact_elastic_n)
        np.testing.assert_allclose(body[:, i], ref.body_force_n, rtol=1e-14, atol=1e-12 * float(np.max(total)))
        contacts_j, wall_j = forces.contact_potentials(model, jnp.asarray(x[:, i]), max_overlap)
        elastic_j = float(jnp.sum(contacts_j) + wall_j + forces.preload_potential(model, jnp.asarray(x[:, i])))
        np.testing.assert_allclose(potential[i], elastic_j, rtol=1e-13, atol=1e-15)
        plastic_j = 0.0 if peak is None else float(forces.plastic_dissipation(model, jnp.asarray(x[:, i]), max_overlap))
        np.testing.assert_allclose(plastic[i], plastic_j, rtol=1e-13, atol=1e-15)
        if flags.plastic:
            assert plastic_j > 0.0  # some contacts have yielded
        np.testing.assert_allclose(kinetic[i], 0.5 * float(jnp.sum(model.mass_kg * v[:, i] ** 2)), rtol=1e-14)


@pytest.mark.slow  # default-suite time; `test_solve_batched_without_books_records_the_same_forces` keeps the claim
def test_kernel_without_books_records_the_same_forces():
    """`ledger=False` (what fits run) drops the maxima and the energy books, not the physics:
    the recorded forces of the JAX kernel are bit-identical, the books NaN (the C++ kernel
    fits run instead is held to this one in tests/test_native.py). Bit-identical at XLA's
    default optimisation level, which users run (at the suite's level 0 the two programs round
    differently by ~5e-12)."""
    if rerun_at_the_default_xla_level(__file__, "test_kernel_without_books_records_the_same_forces"):
        return
    from hertzchain.batched import kernel_flags, record_batched

    setup, grid = _batch(**CASES["friction_viscous_preload"])
    recording = Recording((2, 6))
    flags = kernel_flags(setup)
    with_books = record_batched(setup, grid, recording, flags)
    without = record_batched(setup, grid, recording, flags._replace(ledger=False), kernel="jax")
    for name in with_books.channel_names:
        np.testing.assert_array_equal(without.forces_n[name], with_books.forces_n[name])
    assert np.all(np.isnan(without.max_force_n)) and np.all(np.isnan(without.energy_error_j))
    reference = solve_batched(setup, grid, recording, kernel="jax")
    np.testing.assert_array_equal(with_books.max_force_n, reference.max_force_n)


@pytest.mark.parametrize("case", ["elastic", "sensors_preload_viscous"])
def test_solve_batched_without_books_records_the_same_forces(case):
    """`solve_batched(books=False)` (the benchmarks' like-for-like case) on the undamped
    JAX kernel (velocities carried as the next half kick's) and the damped one: the recorded
    forces bit-identical to the run with books, the maxima and energies NaN."""
    setup, grid = _batch(**CASES[case])
    recording = Recording((2, 6))
    with_books = solve_batched(setup, grid, recording, kernel="jax")
    without = solve_batched(setup, grid, recording, books=False, kernel="jax")
    for name in with_books.channel_names:
        np.testing.assert_array_equal(without.forces_n[name], with_books.forces_n[name])
    assert np.all(np.isnan(without.max_force_n)) and np.all(np.isnan(without.initial_energy_j))
    assert np.all(np.isfinite(with_books.max_force_n))


# ------------------------------------------------------------------------------------------
# One definition of each law: every kernel's contact and friction laws held to `contact`.

LAWS = {
    "hertz": dict(viscous=False, springs=False, preload=True, friction=False),
    "hertz_and_sensor_spring": dict(viscous=False, springs=True, preload=True, friction=False),
    "kuwabara_kono_clipped": dict(viscous=True, springs=False, preload=True, friction=False),
    "dashpot_and_kuwabara_kono": dict(viscous=True, springs=False, preload=True, friction=False, rate_law="dashpot"),
    "track_friction": dict(viscous=False, springs=False, preload=True, friction=True),
    "all_together": dict(viscous=True, springs=True, preload=True, friction=True, rate_law="dashpot"),
    "power_law": dict(viscous=False, springs=False, preload=True, friction=False, law="power_law"),
    "power_law_damped_and_friction": dict(viscous=True, springs=True, preload=True, friction=True, law="power_law"),
    "thornton": dict(viscous=False, springs=False, preload=True, friction=False, law="thornton"),
    "jackson_green_damped_and_friction": dict(viscous=True, springs=True, preload=True, friction=True,
                                              law="jackson_green"),
    "power_law_dashpot": dict(viscous=True, springs=False, preload=True, friction=False, law="power_law",
                              rate_law="dashpot"),
    "thornton_dashpot_and_friction": dict(viscous=True, springs=False, preload=True, friction=True, law="thornton",
                                          rate_law="dashpot"),
}


def _kernels():
    from hertzchain import native

    built = native.available()
    reason = "no C++ compiler or kernel: JAX kernel only"
    emulated = native.thread_unavailable_reason("emulated")
    return ["jax"] + [pytest.param(k, marks=pytest.mark.skipif(not built, reason=reason))
                      for k in ("native_conservative", "native_full")] + [
        pytest.param(k, marks=pytest.mark.skipif(emulated is not None, reason=str(emulated)))
        for k in ("thread_conservative", "thread_full")]


@pytest.mark.parametrize("kernel", _kernels())
@pytest.mark.parametrize("law", list(LAWS))
def test_every_kernel_applies_the_laws_of_contact(law, kernel):
    """Bodies of infinite mass (inverse mass 0) move at the velocities friction leaves them,
    whatever the forces, so the overlap and its rate at every sample are known from a few
    lines of arithmetic here; each kernel's recorded forces must then be `contact`'s laws
    (`hertz_force`, `spring_force`, `contact_force`, `track_friction_kick`) at those
    overlaps and rates, over approach, separation (the viscous force clipped at zero), stick
    and slip. Chains: approaching fast and slowly, and a preloaded contact separating."""
    from hertzchain import batched, contact
    from hertzchain.timegrid import TimeGrid

    flags = batched.KernelFlags(**LAWS[law], ledger=False)
    if kernel.endswith("_conservative") and flags.full_state:
        pytest.skip("the conservative kernels have no damping or friction (the full ones do)")
    if flags.law != "hertz" and kernel not in ("jax", "native_full"):
        pytest.skip("laws other than Hertz's are in the JAX kernel and the host's full kernel only")
    v0 = np.array([0.8, 0.05, -0.3])  # m/s: striker speeds (the last one moving away)
    batch = v0.size
    ones = np.ones((2, batch))
    p = {
        "mass": ones, "inv_mass": np.zeros((3, batch)),
        "kappa": np.array([[1.2e10] * batch, [3.4e10] * batch]),
        "spring": np.array([[2e8] * batch, [0.0] * batch]) if flags.springs else 0.0 * ones,
        # contact 0: closing from touch, closing from a gap it never closes, preloaded and opening
        "overlap0": np.array([[0.0, -0.3e-6, 2.5e-6], [2e-7] * batch]),
        "eta": np.full(batch, 2e-6 if flags.viscous else 0.0),
        "dashpot": np.full(batch, 40.0 if flags.rate_law == "dashpot" else 0.0),  # N s/m: a tenth of the elastic force
        "friction": np.full(batch, 0.19 * 9.81 * 5e3 if flags.friction else 0.0),  # strong: stops the slow one
        "external": np.zeros((3, batch)), "first_force": np.zeros(batch), "last_force": np.zeros(batch),
        "v0": v0,
    }
    if flags.law == "power_law":  # n = 1.7 about a reference overlap of 1 um
        p |= {"exponent": np.full(batch, 1.7), "reference_overlap_m": np.full(batch, 1e-6)}
    # elastic-plastic: contact 0 leaves Hertz at about 1.5 um, past the preload's 2.5 um (the
    # striker moving away unloads it along the flattened curve) and within the fast striker's
    # reach (loading); the wall contact stays elastic
    if flags.law == "thornton":
        p |= {"yield_force_n": np.array([[22.0] * batch, [np.inf] * batch])}
    if flags.law == "jackson_green":
        p |= {"yield_force_n": np.array([[1.0] * batch, [np.inf] * batch]),
              "reduced_radius_m": np.full((2, batch), 2.5e-3), "poisson": np.full((2, batch), 0.28),
              "yield_stress_pa": np.full(batch, 1.3e9)}
    p = {k: jnp.asarray(v) for k, v in p.items()}
    grid = TimeGrid(dt_s=1e-7, steps_per_sample=3, n_samples=40)
    if kernel == "jax":
        traces, _, _ = batched._kernel(p, flags=flags, grid=grid, rows=(0,), block_steps=6)
    else:
        from hertzchain import native

        backend, physics = kernel.split("_")
        which = native.FusedKernel(physics, "host" if backend == "native" else "emulated")
        traces, _, _ = batched._native_kernel(p, flags=flags, grid=grid, rows=(0,), which=which)

    # The same motion, written out: x += dt kick(v), v = kick(kick(v)) (the forces move nothing).
    h = 0.5 * grid.dt_s
    kick = (lambda w: np.asarray(contact.track_friction_kick(w, p["friction"], h))) if flags.friction else (
        lambda w: w)
    x, v = np.zeros((3, batch)), np.zeros((3, batch))
    v[0] = v0
    peak = np.asarray(p["overlap0"])  # largest overlaps so far (elastic-plastic laws)
    expected, elastic, damped, hertz = [], [], [], []
    for _ in range(grid.n_samples):
        for _ in range(grid.steps_per_sample):
            w = kick(v)
            x = x + grid.dt_s * w
            v = kick(w)
            peak = np.maximum(peak, x[:-1] - x[1:] + np.asarray(p["overlap0"]))
        overlap = x[:-1] - x[1:] + np.asarray(p["overlap0"])
        rate = v[:-1] - v[1:]
        if flags.law == "power_law":
            law = contact.power_law_force(overlap, p["kappa"], p["exponent"], p["reference_overlap_m"])
        elif flags.law == "thornton":
            law = np.where(np.isfinite(p["yield_force_n"]), contact.thornton_contact(
                overlap, peak, p["kappa"], jnp.where(np.isfinite(p["yield_force_n"]), p["yield_force_n"], 1.0))[0],
                contact.hertz_force(overlap, p["kappa"]))
        elif flags.law == "jackson_green":  # its constants as `forces.elastic_parts` gives them
            law = np.where(np.isfinite(p["yield_force_n"]), contact.jackson_green_contact(
                overlap, peak, p["kappa"], p["reduced_radius_m"], p["yield_stress_pa"], p["poisson"])[0],
                contact.hertz_force(overlap, p["kappa"]))
        else:
            law = contact.hertz_force(overlap, p["kappa"])
        if flags.viscous:
            force = contact.contact_force(overlap, rate, p["kappa"], p["eta"], law, dashpot_n_s_m=p["dashpot"])[1]
            damped.append(np.asarray(force))
        else:
            force = law
        if flags.springs:
            force = force + contact.spring_force(overlap, p["spring"])
        expected.append(np.asarray(force))
        elastic.append(np.asarray(law))
        hertz.append(np.asarray(contact.hertz_force(overlap, p["kappa"])))
    # (contacts, B, n_samples)
    expected, elastic, damped, hertz = (np.stack(a, axis=-1) if a else None for a in (expected, elastic, damped, hertz))
    scale = np.max(np.abs(expected))
    assert scale > 1.0 and np.any(elastic[0] == 0.0)  # loaded contacts, and an open one
    if flags.plastic:  # contact 0 yields on loading (below Hertz) and opens above zero overlap on unloading
        assert elastic[0, 0, -1] < 0.9 * hertz[0, 0, -1] and np.any((elastic[0, 2] == 0.0) & (hertz[0, 2] > 0.0))
    if flags.viscous:  # the clip at zero acts: an opening contact with elastic force left
        assert np.any((elastic[0] > 0) & (damped[0] == 0.0))
    if flags.friction:  # the slow striker sticks
        assert v[0, 1] == 0.0 and v[0, 0] > 0.0
    for c, trace in enumerate(traces):
        np.testing.assert_allclose(np.asarray(trace), expected[c], rtol=0, atol=1e-12 * scale)
