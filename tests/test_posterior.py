"""The posterior sampler against what it must reproduce where the answer is known.

Data: a brass chain (not the paper's steel) simulated by the diffrax reference solver and
recorded through `hertzchain.acquisition` (another integrator and another writer than the
fit's model). Checked against independent numbers:

- with nothing uncertain but the noise, the posterior's means are the least-squares
  optimum and its sds the Cramér-Rao standard errors of `fitting.design` (20 %);
- with tolerance priors on the sensor gains and the bead radius, the marginal sds are
  those of a linearised propagation written here in NumPy from the Jacobian without the
  priors, plus the prior precision (20 %);
- the outputs (`posterior.json` keys, draws, InferenceData) are whole and consistent.
"""

import functools
import json
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting
import hertzchain as hc
from fitting.design import design
from fitting.model import residuals_and_jacobian
from fitting.posterior import PosteriorWarning, compare_with_laplace, sample_posterior
from hertzchain.acquisition import Acquisition, acquire_trace
from hertzchain.io.tracefile import TraceFile
from hertzchain.materials import BRASS
from hertzchain.reference import simulate_reference

ETA_S = 1.5e-6
NOISE_N = 0.05


def _brass(velocity, n_beads=8, **extra):
    values = dict(eta_s=ETA_S) | extra
    return hc.ChainSetup(n_beads, bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                         bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                         striker_radius_m=4e-3, striker_velocity_m_s=velocity, **values)


@pytest.fixture(scope="module")
def brass_traces():
    traces = []
    for k, velocity in enumerate((0.2, 0.5)):
        setup = _brass(velocity)
        sim = simulate_reference(setup, t_end_s=0.45e-3, sample_interval_s=0.25e-6, contacts=(3,), rtol=1e-9)
        forces = {name: np.asarray(sim.forces_n[name]) for name in sim.channel_names}
        setting = Acquisition(sample_interval_s=1e-6, record_length=400, pre_trigger_samples=20,
                              noise_std_n=NOISE_N, coupling="dc")
        trace = acquire_trace(setup, np.asarray(sim.time_s), forces, setting, seed=10 + k)
        traces.append(trace)
    return traces


@pytest.fixture(scope="module")
def noise_only(brass_traces):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PosteriorWarning)
        return sample_posterior(brass_traces, ("eta_s", "C"), chains=2, warmup=80, draws=150, seed=3,
                                progress=False)


@pytest.mark.slow  # the noise-only posterior (its sampling, about 30 s on 2 cores) with `-m slow`: default-suite time
def test_noise_only_posterior_is_the_optimum_with_cramer_rao_widths(noise_only, brass_traces):
    result = noise_only
    assert result.fit.converged and result.fit.reduced_chi2 < 1.2
    bound = design(brass_traces, ("eta_s", "C"), values={"eta_s": result.fit.values["eta"],
                                                         "C": result.fit.values["C"]})
    for label in ("eta", "C"):
        row = result.summary[label]
        crb = bound.stderr[label]
        assert row["sd"] == pytest.approx(crb, rel=0.2), label
        assert abs(row["mean"] - result.fit.values[label]) < 0.25 * crb, label
        assert row["r_hat"] < 1.02
    # the truth is inside the 90 % interval for eta (the diffrax data's eta)
    assert result.summary["eta"]["q05"] < ETA_S < result.summary["eta"]["q95"]
    assert result.divergences == 0


@pytest.mark.slow
def test_tolerance_priors_widen_as_linear_propagation_predicts(brass_traces):
    priors = ["sensor_gain=+-2%", "bead_radius_m=+-0.5%"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PosteriorWarning)
        result = sample_posterior(brass_traces, ("eta_s", "C"), priors=priors, chains=2, warmup=80,
                                  draws=250, seed=4, progress=False)
    # linear propagation: J of the data residuals alone, prior precision added by hand
    plain = fitting.make_problem(brass_traces, ("eta_s", "C", "sensor_gain", "bead_radius_m"))
    assert plain.labels == result.labels
    _, jac = residuals_and_jacobian(plain, result.fit.x)
    prior_sd = {"bead_radius": 0.005 * 5e-3, "sensor_gain[contact_3]": 0.02, "sensor_gain[wall]": 0.02}
    precision = jac.T @ jac + np.diag([1 / prior_sd[label] ** 2 if label in prior_sd else 0.0
                                       for label in result.labels])
    linear = np.sqrt(np.diag(np.linalg.inv(precision)))
    widened = 0
    for i, label in enumerate(result.labels):
        assert result.summary[label]["sd"] == pytest.approx(linear[i], rel=0.2), label
    noise_only = np.sqrt(np.diag(np.linalg.inv(jac[:, :2].T @ jac[:, :2])))
    for i, label in enumerate(("eta", "C")):
        widened += result.summary[label]["sd"] > 1.5 * noise_only[i]
    assert widened >= 1  # the tolerances matter: at least one of eta, C is much wider


def _potentials(fit_result):
    """The sampler's potential at a MAP fit (`fitting.posterior._potential`), and a
    function that writes the same potential plainly from a residual function of x."""
    from fitting.parameters import from_unbounded, transform_arrays
    from fitting.posterior import _laplace_whitening, _potential

    problem = fit_result.problem
    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    z_hat, chol = _laplace_whitening(problem.instances, constants, np.asarray(fit_result.x),
                                     fit_result.covariance)

    def plain_with(residuals):
        def plain(u):
            z = z_hat + chol @ u
            x, dx_dz = jax.jvp(lambda zz: from_unbounded(constants, zz), (z,), (jnp.ones_like(z),))
            return 0.5 * jnp.sum(residuals(x) ** 2) - jnp.sum(jnp.log(jnp.abs(dx_dz)))

        return plain

    return problem, _potential(problem, constants, z_hat, chol), plain_with


@pytest.mark.slow  # the noise-only posterior (its sampling, about 30 s on 2 cores) with `-m slow`: default-suite time
def test_potential_gradient_matches_reverse_mode_and_central_differences(noise_only):
    """The sampler's forward-mode gradient against jax.grad of the same potential written
    without the sampler's custom rule (reverse mode through the residuals), and against
    central differences, at a point one Laplace sd off the optimum in every whitened direction."""
    problem, potential, plain_with = _potentials(noise_only.fit)
    plain = plain_with(problem.residuals)
    u = jnp.array([1.0, -0.7])
    value, gradient = jax.value_and_grad(potential)(u)
    assert float(value) == pytest.approx(float(plain(u)), rel=1e-12)
    reverse = np.asarray(jax.grad(plain)(u))
    np.testing.assert_allclose(np.asarray(gradient), reverse, rtol=1e-8)
    step = 1e-4
    for i in range(2):
        e = jnp.zeros(2).at[i].set(step)
        central = (float(plain(u + e)) - float(plain(u - e))) / (2 * step)
        assert float(gradient[i]) == pytest.approx(central, rel=1e-5)
    # vectorised chains call it under vmap: all chains in one simulation (its batching
    # rule), each chain's value and gradient those of its own reverse-mode evaluation
    batch = jnp.stack([u, -u, 0.5 * u])
    values, gradients = jax.vmap(jax.value_and_grad(potential))(batch)
    for k in range(3):
        assert float(values[k]) == pytest.approx(float(plain(batch[k])), rel=1e-12)
        np.testing.assert_allclose(np.asarray(gradients[k]), np.asarray(jax.grad(plain)(batch[k])), rtol=1e-8)


@pytest.mark.slow  # the noise-only posterior (its sampling, about 30 s on 2 cores) with `-m slow`: default-suite time
def test_sampler_gradient_on_the_cpp_kernel_equals_reverse_mode_through_the_jax_kernel(noise_only, monkeypatch):
    """The gradient NUTS takes (forward mode: the C++ kernel's tangents, all the chains and
    directions in one kernel run) against `jax.grad` of the same potential through the JAX
    kernel's own reverse mode (another code path: the scan integrated forward, its adjoint
    backward), to 1e-8 relative, one chain alone and three chains under `vmap`."""
    from hertzchain import native

    if not native.available():
        pytest.skip(f"no native kernel: {native.unavailable_reason()}")
    problem, potential, plain_with = _potentials(noise_only.fit)
    u = jnp.array([1.0, -0.7])
    batch = jnp.stack([u, -u, 0.5 * u])
    sampler = jax.jit(jax.vmap(jax.value_and_grad(potential)))
    hlo = sampler.lower(batch).as_text()
    assert hlo.count("hertzchain_chain_full_tangent") == 1 and "while" not in hlo  # one kernel run
    values, gradients = sampler(batch)

    # the reference: a new problem (its own compiled functions) on the JAX kernel
    monkeypatch.setattr(native, "kernel_for", lambda flags, devices, rows=None: None)
    reference = problem.with_setups(problem.base_setups)
    # JAX's own differentiation of the kernel (not the model's custom JVP)
    plain = plain_with(lambda x: reference.residuals(x, directional=True))
    reverse = jax.jit(jax.value_and_grad(plain))
    assert "hertzchain_chain" not in reverse.lower(u).as_text()
    for k in range(3):
        value, gradient = reverse(batch[k])
        assert float(values[k]) == pytest.approx(float(value), rel=1e-12)
        np.testing.assert_allclose(np.asarray(gradients[k]), np.asarray(gradient), rtol=1e-8)


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it (the draw-for-draw test below starts from the same state)
def test_compiled_sampler_start_equals_numpyros_eager_start(noise_only):
    """`_run_chains` starts its chains with `_nuts`'s `init` (NumPyro's functional NUTS),
    vectorised and compiled; on a real potential (C++ kernel's tangents, interpolation, gains,
    transforms) its starting state must be `NUTS.init`'s, run eagerly, to 1e-9 relative:
    potential, gradient, energy and the heuristic step size. (Bit for bit is not promised:
    XLA fuses the compiled evaluation, as it does in every later step.)"""
    from numpyro.infer import NUTS

    from fitting.posterior import _nuts

    _, potential, _ = _potentials(noise_only.fit)
    starts = jnp.array([[1.0, -0.7], [-0.4, 0.3]])
    keys = jax.random.split(jax.random.PRNGKey(3), 2)
    eager = NUTS(potential_fn=potential, target_accept_prob=0.8, max_tree_depth=8, dense_mass=False,
                 adapt_mass_matrix=False, find_heuristic_step_size=True).init(
        keys, 20, starts, model_args=(), model_kwargs={})
    init, _ = _nuts(potential, warmup=20, target_accept=0.8, max_tree_depth=8, adapt_metric=False)
    compiled = jax.jit(jax.vmap(init))(starts, keys)
    for name in ("potential_energy", "z_grad", "energy"):
        np.testing.assert_allclose(np.asarray(getattr(compiled, name)), np.asarray(getattr(eager, name)),
                                   rtol=1e-9, err_msg=name)
    np.testing.assert_allclose(np.asarray(compiled.adapt_state.step_size),
                               np.asarray(eager.adapt_state.step_size), rtol=1e-9)
    np.testing.assert_array_equal(np.asarray(compiled.z), np.asarray(starts))


def test_chains_in_lockstep_evaluate_the_gradient_only_for_their_trees():
    """Vectorised as `NUTS.sample` vectorises it (the iteration count per chain), NumPyro's
    iteration evaluates both sides of its adaptation's branches: the step-size search ran,
    and was thrown away, at every iteration, draws included. In lockstep (`_lockstep_axes`)
    the potential is evaluated for the trees' leapfrog steps only: per iteration at most one
    evaluation per chain more than the largest tree of the batch (a chain whose tree is done
    waits for the others). Measured on this target over 30 draws of 3 chains: 462
    evaluations in lockstep, 978 vectorised per chain, the bound 546."""
    from fitting.posterior import _lockstep_axes, _nuts, _shared_fields

    calls = [0]

    def potential(u):
        jax.debug.callback(lambda _: calls.__setitem__(0, calls[0] + 1), u[0])
        x = u[0] + 0.3 * u[1] ** 2
        return 0.5 * (x**2 + (u[1] - 0.5 * u[2]) ** 2 / 0.3 + u[2] ** 2)

    chains, warmup = 3, 30
    init, step = _nuts(potential, warmup=warmup, target_accept=0.8, max_tree_depth=6, adapt_metric=False)
    state = jax.jit(jax.vmap(init))(0.5 * jax.random.normal(jax.random.PRNGKey(1), (chains, 3)),
                                    jax.random.split(jax.random.PRNGKey(7), chains))
    axes = _lockstep_axes(state)
    state = _shared_fields(state)
    iterate = jax.jit(jax.vmap(step, in_axes=(axes,), out_axes=axes))
    for _ in range(warmup):
        state = iterate(state)
    jax.block_until_ready(state)
    calls[0], largest_trees = 0, 0
    for _ in range(30):
        state = jax.block_until_ready(iterate(state))
        largest_trees += int(np.max(state.num_steps))
    assert int(state.i) == warmup + 30
    assert chains * largest_trees <= calls[0] <= chains * (largest_trees + 30)


def test_laplace_comparison_flags_a_skewed_marginal():
    summary = {"a": {"sd": 1.0, "q05": -1.645, "q50": 0.0, "q95": 1.645},
               "b": {"sd": 1.0, "q05": -1.0, "q50": 0.0, "q95": 2.3}}
    out = compare_with_laplace(summary, {"a": 0.0, "b": 0.0}, {"a": 1.0, "b": 1.0})
    assert not out["a"]["fails"] and out["b"]["fails"]
    assert out["b"]["upper_ratio"] == pytest.approx(2.3 / 1.6448536, rel=1e-6)


@pytest.mark.slow  # the noise-only posterior (its sampling, about 30 s on 2 cores) with `-m slow`: default-suite time
def test_report_files_are_whole_and_agree(noise_only, tmp_path):
    from fitting.posterior_report import write_posterior_report

    written = write_posterior_report(noise_only, tmp_path)
    names = {p.name for p in written}
    assert {"posterior.json", "posterior.nc", "draws.csv", "posterior_summary.md", "posterior_pairs.png",
            "posterior_trace.png"} <= names
    report = json.loads((tmp_path / "posterior.json").read_text())
    assert list(report["params"]) == list(report["laplace"]) == list(report["priors"]) == ["eta_s", "C"]
    assert set(report["map"]) == {"eta_s", "C"}
    for label in ("eta_s", "C"):
        entry = report["params"][label]
        assert set(entry) >= {"mean", "sd", "q05", "q50", "q95", "r_hat", "ess", "unit"}
        assert entry["mean"] == pytest.approx(noise_only.summary[label]["mean"], rel=1e-12)
    assert (tmp_path / "draws.csv").read_text().splitlines()[0] == "chain,draw,eta_s,C"
    draws = np.genfromtxt(tmp_path / "draws.csv", delimiter=",", names=True)
    assert draws.size == 2 * 150
    assert np.mean(draws["eta_s"]) == pytest.approx(report["params"]["eta_s"]["mean"], rel=1e-9)
    assert "| eta_s | s |" in (tmp_path / "posterior_summary.md").read_text()
    import arviz as az

    idata = az.from_netcdf(tmp_path / "posterior.nc")
    assert idata.posterior["C"].shape == (2, 150) and idata.posterior["eta_s"].attrs["label"] == "eta_s"
    assert math.isclose(float(idata.posterior["C"].mean()), report["params"]["C"]["mean"], rel_tol=1e-12)
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; the strict exit of the CLI; the posterior's own diagnostics are tested in the default suite
def test_command_line_posterior_is_strict_about_too_few_draws(brass_traces, tmp_path):
    from hertzchain.cli import main
    from hertzchain.io.tracefile import write_trace

    path = tmp_path / "shot.csv"
    write_trace(path, brass_traces[1])
    out = tmp_path / "out"
    base = ["fit", str(path), "--params", "eta_s", "--quiet", "--no-plots", "--out", str(out)]
    assert main(base + ["--posterior", "--covariance", "residual"]) == 2
    # 2 x 20 draws cannot reach an ESS of 400: a loud failure, exit 4 with --strict
    code = main(base + ["--posterior", "--chains", "2", "--warmup", "20", "--draws", "20", "--strict",
                        "--prior", "sensor_gain=+-2%"])
    assert code == 4
    report = json.loads((out / "posterior.json").read_text())
    assert not report["diagnostics_passed"]
    assert any("ESS" in text for text in report["failed_diagnostics"])
    assert set(report["params"]) == {"eta_s", "sensor_gain[contact_3]", "sensor_gain[wall]"}
    assert report["priors"]["sensor_gain[wall]"]["sd"] == pytest.approx(0.02)


@pytest.mark.slow  # a new process compiles the model and the sampler again (about a minute)
def test_command_line_posterior_splits_chains_over_the_cpu_cores(brass_traces, noise_only, tmp_path):
    """`hertzchain fit --posterior` as a user runs it (a new process): the CPU's cores become
    JAX devices and the chains are split between them, each group its own program; the
    result is the same posterior as the one-device run in this process (means within 0.3
    sd, sds within 20 %, no divergences)."""
    import os
    import subprocess
    import sys

    from hertzchain.io.tracefile import write_trace

    paths = []
    for k, trace in enumerate(brass_traces):
        paths.append(tmp_path / f"shot{k}.csv")
        write_trace(paths[-1], trace)
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_NUM_CPU_DEVICES")}
    command = [sys.executable, "-m", "hertzchain", "fit", *map(str, paths), "--params", "eta_s,C", "--quiet",
               "--no-plots", "--out", str(out), "--posterior", "--chains", "2", "--warmup", "80",
               "--draws", "150", "--seed", "5"]
    proc = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads((out / "posterior.json").read_text())
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert report["settings"]["devices"] == min(cores, 2)
    assert report["divergences"] == 0
    for label in ("eta_s", "C"):
        ours, one_device = report["params"][label], noise_only.summary[label]
        assert ours["sd"] == pytest.approx(one_device["sd"], rel=0.2), label
        assert abs(ours["mean"] - one_device["mean"]) < 0.3 * one_device["sd"], label


# --- slow: a single low-amplitude shot; calibration over data sets drawn from the prior ---------
@pytest.mark.slow
def test_low_amplitude_shot_alone_breaks_the_laplace_approximation(tmp_path):
    """One shot at 1 cm/s (peak force below 1 N, noise 0.05 N): damping and friction both
    take amplitude from the pulse, and friction is only bounded by its lower bound 0; the
    posterior of mu is cut there, so its 90 % interval is not the Laplace one, and the report
    says so."""
    from fitting.posterior_report import write_posterior_report

    setup = _brass(0.01, eta_s=0.1e-6, mu=0.001)
    sim = simulate_reference(setup, t_end_s=1.1e-3, sample_interval_s=0.25e-6, contacts=(3,), rtol=1e-9)
    forces = {name: np.asarray(sim.forces_n[name]) for name in sim.channel_names}
    setting = Acquisition(sample_interval_s=1e-6, record_length=1000, pre_trigger_samples=20,
                          noise_std_n=NOISE_N, coupling="dc")
    trace = acquire_trace(setup, np.asarray(sim.time_s), forces, setting, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PosteriorWarning)
        result = sample_posterior([trace], ("eta_s", "mu"), chains=2, warmup=150, draws=300, seed=1,
                                  progress=False)
    mu = result.laplace["mu"]
    assert mu["fails"]
    # the lower half of the interval is the one the bound cuts
    assert mu["lower_ratio"] < 1 - 0.2
    assert result.summary["mu"]["q05"] > 0
    assert np.corrcoef(result.flat_draws().T)[0, 1] < -0.2  # damping and friction trade off
    write_posterior_report(result, tmp_path, plots=False)
    summary = (tmp_path / "posterior_summary.md").read_text()
    assert "the covariance (Laplace) approximation fails for mu" in summary


_CALIBRATION_PRIORS = ("eta_s=1.5us+-0.3us", "C=+-1%")


def _calibration_posterior(trace, seed):
    """One data set's posterior (in a worker process): thinned draws and 90 % intervals."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PosteriorWarning)
        result = sample_posterior([trace], ("eta_s", "C"), priors=_CALIBRATION_PRIORS, chains=2, warmup=150,
                                  draws=200, seed=seed, progress=False)
    thinned = result.draws[:, ::4, :].reshape(-1, 2)  # 100 draws, nearly independent
    intervals = [(result.summary[label]["q05"], result.summary[label]["q95"]) for label in result.labels]
    return thinned, intervals


@pytest.mark.slow
def test_posterior_intervals_are_calibrated_over_data_drawn_from_the_prior():
    """Simulation-based calibration: 60 data sets, each from a truth drawn from the priors
    (eta 1.5 +- 0.3 us, C +- 1 %) and the noise; the rank of each truth among thinned draws
    of its posterior is uniform (chi^2 of 4 bins below its 0.1 % point) and the 90 %
    intervals cover it 54 times in 60 within 3 binomial sigma. Chains of 2 x 200 draws after
    150 warmup: with 2 x 100 after 60 (ESS about 150) the sds came out 3-15 % narrow and C's
    intervals covered 47 of 60. Each posterior runs in a
    worker process (two at a time, fresh processes every few data sets: every data set is a
    new compilation)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    setup = _brass(0.3, n_beads=5)
    sim = simulate_reference(setup, t_end_s=0.3e-3, sample_interval_s=0.25e-6, contacts=(2,), rtol=1e-9)
    forces = {name: np.asarray(sim.forces_n[name]) for name in sim.channel_names}
    setting = Acquisition(sample_interval_s=1e-6, record_length=250, pre_trigger_samples=10,
                          noise_std_n=NOISE_N, coupling="dc")
    base = acquire_trace(setup, np.asarray(sim.time_s), forces, setting, seed=0)
    problem = fitting.make_problem([base], ("eta_s", "C"), priors=_CALIBRATION_PRIORS)
    centre = np.array([row.centre for row in problem.priors])
    sd = np.array([row.sd for row in problem.priors])
    n_sets, rng = 60, np.random.default_rng(2024)
    truths, traces = [], []
    for _ in range(n_sets):
        truth = centre + sd * rng.standard_normal(2)
        model = np.asarray(problem.model_vector(truth))
        channels, start = {}, 0
        for name in base.channel_names:
            n = len(base.time_s)
            channels[name] = model[start:start + n] + NOISE_N * rng.standard_normal(n)
            start += n
        truths.append(truth)
        traces.append(TraceFile(dict(base.header), base.time_s, channels))
    results = []
    for first in range(0, n_sets, 6):  # a fresh pair of processes every 6 data sets
        with ProcessPoolExecutor(max_workers=2, mp_context=multiprocessing.get_context("spawn")) as pool:
            results += pool.map(_calibration_posterior, traces[first:first + 6], range(first, first + 6))
    ranks = np.array([np.sum(thinned < truth[None, :], axis=0) for (thinned, _), truth in zip(results, truths)])
    covered = np.sum([[low < truth[i] < high for i, (low, high) in enumerate(intervals)]
                      for (_, intervals), truth in zip(results, truths)], axis=0)
    expected = n_sets / 4
    for i in range(2):
        counts = np.histogram(ranks[:, i], bins=4, range=(0, 101))[0]
        assert np.sum((counts - expected) ** 2 / expected) < 16.27, counts
        sigma = math.sqrt(n_sets * 0.9 * 0.1)
        assert abs(covered[i] - 0.9 * n_sets) < 3 * sigma, covered


# vectorised chains (what `posterior` runs) in the default suite; one chain with an adapted
# metric (`adapt_metric`, not the default) with `-m slow` (suite time)
# one chain in the default suite, three (the chains in lockstep) with `-m slow`: default-suite time
@pytest.mark.parametrize("chains", [1, pytest.param(3, marks=pytest.mark.slow)])
def test_chains_driven_here_are_numpyros_mcmc_draw_for_draw(chains):
    """`_run_chains` calls NumPyro's NUTS kernel itself (a compiled `init`, one compiled
    iteration for warmup and draws, the chains in lockstep); its tree sizes and divergences
    must be those of `numpyro.infer.MCMC` (eager `init`, warmup, then run from the warmed
    state) to the bit, and its draws, statistics and step sizes to 1e-9 relative, on a
    correlated, skewed target. (The lockstep iteration is another XLA program than MCMC's
    vectorised one: measured, they round apart by 4e-13 relative in 40 draws.)"""
    from numpyro.infer import MCMC, NUTS

    from fitting.posterior import _run_chains

    def potential(u):
        x = u[0] + 0.3 * u[1] ** 2
        return 0.5 * (x**2 + (u[1] - 0.5 * u[2]) ** 2 / 0.3 + u[2] ** 2) + 0.1 * jnp.sum(jnp.abs(u) ** 3)

    starts = 0.5 * jax.random.normal(jax.random.PRNGKey(1), (chains, 3))
    key = jax.random.PRNGKey(7)
    settings = dict(target_accept=0.8, max_tree_depth=6, adapt_metric=chains == 1)
    ours = _run_chains(starts, key, potential=potential, warmup=30, draws=40, progress=False, **settings)

    kernel = NUTS(potential_fn=potential, target_accept_prob=0.8, max_tree_depth=6, dense_mass=False,
                  adapt_mass_matrix=chains == 1, find_heuristic_step_size=True)
    mcmc = MCMC(kernel, num_warmup=30, num_samples=40, num_chains=chains, chain_method="vectorized",
                progress_bar=False)
    mcmc.warmup(key, init_params=starts if chains > 1 else starts[0], extra_fields=("num_steps",),
                collect_warmup=True)
    warmup_steps = int(np.sum(mcmc.get_extra_fields(group_by_chain=True)["num_steps"]))
    mcmc.run(mcmc.post_warmup_state.rng_key,
             extra_fields=("diverging", "num_steps", "accept_prob", "potential_energy"))
    theirs = np.asarray(mcmc.get_samples(group_by_chain=True)).reshape(chains, 40, -1)
    np.testing.assert_allclose(ours["u"], theirs, rtol=1e-9, atol=1e-12)
    for name, values in mcmc.get_extra_fields(group_by_chain=True).items():
        compare = np.testing.assert_array_equal if name in ("num_steps", "diverging") else \
            functools.partial(np.testing.assert_allclose, rtol=1e-9, atol=1e-12)
        compare(ours["stats"][name], np.asarray(values).reshape(chains, 40), err_msg=name)
    assert ours["warmup_steps"] == warmup_steps
    np.testing.assert_allclose(ours["step_size"],
                               np.asarray(mcmc.last_state.adapt_state.step_size).reshape(-1), rtol=1e-9)
    assert ours["warmed"] < ours["ended"]
    assert len(np.unique(theirs[0, :, 0])) > 5  # the chains moved
