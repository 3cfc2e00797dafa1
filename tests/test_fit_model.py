"""The forward model of fits: consistency with the simulator, interpolation, Jacobian."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fitting
from fitting.model import interpolate
from fitting.parameters import bare_speed_constant
from fitting.synthetic import paper_setups, synthetic_traces

TRUTH = {"eta": 2e-6, "mu": 0.19, "mu_star": 0.02}


@pytest.fixture(scope="module")
def small_problem():
    """One file (V0 = 0.2 m/s, contact 5 and the wall, 1.4 ms), trigger offset 2 us, gain 1.05."""
    setups = paper_setups([0.2], eta_s=TRUTH["eta"], mu=TRUTH["mu"], mu_star=TRUTH["mu_star"])
    files = synthetic_traces(setups, contacts=(5,), t_end_s=1.4e-3, noise_std_n=0.2,
                             time_offset_s=2e-6, gains=[{"contact_5": 1.05}], seed=3)
    params = ("eta_s", "mu", "C", "striker_velocity_m_s", "time_offset_s", "gain")
    problem = fitting.make_problem(files, params)
    c_true = float(bare_speed_constant(setups[0])) * (1 + TRUTH["mu_star"]) ** (1 / 3)
    x_true = np.array([TRUTH["eta"], TRUTH["mu"], c_true, 0.2, 2e-6, 1.05, 1.0])
    return problem, x_true


def test_a_fit_asks_for_the_kernel_of_its_chains_length(small_problem, monkeypatch):
    """`simulates_natively` names each group's chain length to `kernel_for` (on a GPU it builds
    that length's thread kernel to answer): the rows of the kernel arrays the batched kernel
    makes for the group, which `kernel_rows` knows from the setup's shape (sensor beads as two
    bodies, a free end keeping its row)."""
    import hertzchain as hc
    from hertzchain import native
    from hertzchain.batched import kernel_params, kernel_rows, stack_setups

    for changes in ({}, {"end": "free"}, {"sensor_beads": (3, 7)}):
        setups = stack_setups([hc.ChainSetup(9, **changes), hc.ChainSetup(9, striker_velocity_m_s=0.5, **changes)])
        assert kernel_rows(setups) == kernel_params(setups)["inv_mass"].shape[-2]
    problem, _ = small_problem
    asked = []
    monkeypatch.setattr(native, "kernel_for", lambda flags, devices, rows=None: asked.append(rows) or None)
    assert not problem.simulates_natively()
    assert asked == [kernel_params(group.setups)["inv_mass"].shape[-2] for group in problem.groups] == [23]


def test_interpolation_is_third_order():
    errors = []
    for n in (50, 100, 200):
        grid = np.linspace(0, 1, n + 1)
        values = jnp.sin(3 * grid) ** 2
        query = jnp.linspace(0.05, 0.95, 101)
        approx = interpolate(values, query * n)
        errors.append(float(jnp.max(jnp.abs(approx - jnp.sin(3 * query) ** 2))))
    # halving the spacing divides the error by about 8
    assert errors[0] / errors[1] > 6 and errors[1] / errors[2] > 6


def test_residuals_at_the_truth_are_the_noise(small_problem):
    problem, x_true = small_problem
    assert problem.labels == (
        "eta", "mu", "C", "striker_velocity[trace0]", "time_offset[trace0]",
        "gain[trace0:contact_5]", "gain[trace0:wall]",
    )
    residuals = jax.jit(problem.residuals)
    r = np.asarray(residuals(x_true))
    # whitened residuals at the true parameters are unit white noise (2800 samples)
    assert np.mean(r**2) == pytest.approx(1.0, abs=0.1)
    # and the model is not trivially matching: 10 % off in eta is visible
    x_off = x_true.copy()
    x_off[0] *= 1.1
    assert np.mean(np.asarray(residuals(x_off)) ** 2) > 1.5


def test_jacobian_matches_finite_differences(small_problem):
    problem, x_true = small_problem
    _, jac = fitting.residuals_and_jacobian(problem, x_true)
    assert jac.shape == (problem.n_residuals, len(x_true))
    residuals = jax.jit(problem.residuals)
    for j in range(len(x_true)):
        h = 1e-5 * abs(x_true[j])
        up, down = x_true.copy(), x_true.copy()
        up[j] += h
        down[j] -= h
        fd = (np.asarray(residuals(up)) - np.asarray(residuals(down))) / (2 * h)
        scale = np.linalg.norm(fd)
        assert scale > 0
        # (the Coulomb stick-slip switches make the residual only piecewise smooth)
        assert np.linalg.norm(jac[:, j] - fd) / scale < 1e-3, problem.labels[j]


def test_chosen_columns_equal_the_full_jacobian(small_problem):
    """Directional forward mode (a few columns) gives the same columns as the custom JVP."""
    problem, x_true = small_problem
    _, full = fitting.residuals_and_jacobian(problem, x_true)
    columns = [0, 2, 3, 5]  # eta, C, striker velocity (through the solver), a gain (after it)
    _, some = fitting.residuals_and_jacobian(problem, x_true, columns)
    np.testing.assert_allclose(some[:, columns], full[:, columns], rtol=1e-9,
                               atol=1e-9 * np.abs(full[:, columns]).max())
    others = [j for j in range(len(x_true)) if j not in columns]
    assert np.all(np.isnan(some[:, others]))


# Contact laws of the fits' setups (fixed, not fitted): Hertz, Jackson-Green's and the power
# law with a dashpot (the full C++ kernel's libraries, their tangents). The yield stresses
# make the 0.5 m/s shot yield.
FIT_LAWS = {
    "hertz": {},
    "jackson_green": {"plasticity": True, "plastic_law": "jackson_green", "bead_yield_stress_pa": 0.6e9},
    "power_law_and_dashpot": {"contact_exponent": 1.6, "dashpot_n_s_m": 3.0},
}


# the laws other than Hertz's with `-m slow` (default-suite time; test_contact_plasticity and
# test_power_law_contact hold their batched runs to solve)
@pytest.mark.parametrize("law", [pytest.param(law, marks=pytest.mark.slow) if law != "hertz" else law
                                 for law in FIT_LAWS])
def test_batched_kernel_and_solve_give_the_same_model_and_jacobian(law):
    """Two files (their own striker velocities and offsets): the fit's fast path
    (`record_batched`, the experiments on the SIMD axis, one tangent per local parameter
    for all experiments at once) against `solve` under `vmap` with per-experiment
    Jacobians, the general path a custom forward model takes; for Hertz contacts and for
    elastic-plastic, power-law and dashpot contacts."""
    from fitting.model import ForwardModel
    from hertzchain.integrate import solve

    setups = paper_setups([0.2, 0.5], eta_s=TRUTH["eta"], mu=TRUTH["mu"], mu_star=TRUTH["mu_star"], **FIT_LAWS[law])
    files = synthetic_traces(setups, contacts=(5,), t_end_s=1.4e-3, noise_std_n=0.2, seed=4)
    params = ("eta_s", "mu", "C", "striker_velocity_m_s", "time_offset_s")
    fast = fitting.make_problem(files, params)
    general = fitting.make_problem(files, params, forward=ForwardModel(simulate=lambda s, g, r, e: solve(s, g, r)))
    assert fast.fast_path_flags(fast.groups[0]) is not None
    assert general.fast_path_flags(general.groups[0]) is None
    c = float(bare_speed_constant(setups[0])) * (1 + TRUTH["mu_star"]) ** (1 / 3)
    x = np.array([1.1 * TRUTH["eta"], 0.9 * TRUTH["mu"], c, 0.21, 0.49, 1e-6, -1e-6])
    r_fast, j_fast = fitting.residuals_and_jacobian(fast, x)
    r_general, j_general = fitting.residuals_and_jacobian(general, x)
    np.testing.assert_allclose(r_fast, r_general, rtol=0, atol=1e-9 * np.abs(r_general).max())
    for j, label in enumerate(fast.labels):
        scale = np.abs(j_general[:, j]).max()
        assert scale > 0, label
        np.testing.assert_allclose(j_fast[:, j], j_general[:, j], rtol=0, atol=1e-8 * scale, err_msg=label)



@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; vmapped batches on the kernel are tested by test_native in the default suite
def test_many_parameter_sets_in_one_simulation_equal_each_set_alone():
    """`Problem.residuals_many` (the posterior's chains): 8 parameter sets x 4 files run as
    one batch of 32 chains; each set's residuals and Jacobian equal its own `residuals` and
    their forward-mode Jacobian (round-off: the batch width changes XLA's vector loops)."""
    from fitting.fit import initial_values

    setups = paper_setups([0.1, 0.2, 0.3, 0.4], eta_s=2e-6, mu=0.1, n_beads=8)
    files = synthetic_traces(setups, contacts=(3,), t_end_s=0.6e-3, noise_std_n=0.2, seed=1)
    problem = fitting.make_problem(files, ("eta_s", "mu", "C", "gain"))
    x0 = np.asarray(initial_values(problem, None))
    xs = jnp.asarray(x0 * (1 + 0.01 * np.random.default_rng(0).standard_normal((8, x0.size))))
    many = np.asarray(problem.residuals_many(xs))
    # the sets are independent: a tangent that moves parameter j of every set at once
    jac_many = np.asarray(jax.jacfwd(lambda d: problem.residuals_many(xs + d))(jnp.zeros(x0.size)))
    scale = np.max(np.abs(many))
    for k in (0, 5):
        alone = np.asarray(problem.residuals(xs[k]))
        np.testing.assert_allclose(many[k], alone, rtol=0, atol=1e-12 * scale)
        jac_alone = np.asarray(jax.jacfwd(problem.residuals)(xs[k]))
        np.testing.assert_allclose(jac_many[k], jac_alone, rtol=1e-10, atol=1e-12 * np.max(np.abs(jac_alone)))
    assert not np.allclose(many[0], many[5])  # the sets differ
