"""The one Gauss-Newton covariance routine against the closed forms of linear least squares."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain.covariance import gauss_newton_covariance, information_rows


def _line_fit(seed=0, n=40):
    """A straight line y = a + b t with noise: design, data, the least-squares residual sigma."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 3e-3, n)  # seconds: columns of very different norms
    design = np.column_stack([np.ones(n), t])
    y = 2.0 + 500.0 * t + rng.normal(0, 0.01, n)
    coef = np.linalg.solve(design.T @ design, design.T @ y)
    sigma = np.sqrt(np.sum((y - design @ coef) ** 2) / (n - 2))
    return t, design, sigma


def test_linear_least_squares_closed_form():
    t, design, sigma = _line_fit()
    result = gauss_newton_covariance(design, residual_std=sigma)
    expected = sigma**2 * np.linalg.inv(design.T @ design)
    np.testing.assert_allclose(result.covariance, expected, rtol=1e-10)
    # the slope's textbook standard error sigma / sqrt(S_tt)
    s_tt = np.sum((t - t.mean()) ** 2)
    assert result.stderr[1] == pytest.approx(sigma / np.sqrt(s_tt), rel=1e-10)
    assert result.rank == 2
    # condition of the column-normalised design: sqrt of the ratio of its Gram matrix's eigenvalues
    normalised = design / np.linalg.norm(design, axis=0)
    eig = np.linalg.eigvalsh(normalised.T @ normalised)
    assert result.condition == pytest.approx(np.sqrt(eig[-1] / eig[0]), rel=1e-8)


def test_rank_deficient_names_the_unseen_parameters_and_keeps_the_estimable_one():
    rng = np.random.default_rng(1)
    u, w = rng.normal(size=30), rng.normal(size=30)
    jac = np.column_stack([u, 2.0 * u, w])  # x0 and x1 only as x0 + 2 x1
    result = gauss_newton_covariance(jac, residual_std=0.3)
    assert result.rank == 2
    assert np.isinf(result.stderr[0]) and np.isinf(result.stderr[1])
    # x2 is estimable: its variance is that of the reduced, full-rank problem [u, w]
    reduced = 0.3**2 * np.linalg.inv(np.column_stack([u, w]).T @ np.column_stack([u, w]))
    assert result.stderr[2] == pytest.approx(np.sqrt(reduced[1, 1]), rel=1e-9)
    # so is x0 + 2 x1, with the variance of the reduced problem's first coefficient
    c = np.array([1.0, 2.0, 0.0])
    assert c @ result.covariance @ c == pytest.approx(reduced[0, 0], rel=1e-9)
    # the dropped direction is the null space of J: (2, -1, 0) in normalised coordinates
    null = result.directions[~result.kept][0]
    assert np.allclose(np.abs(null), [1 / np.sqrt(2), 1 / np.sqrt(2), 0.0], atol=1e-9)


def test_zero_column_and_fewer_rows_than_parameters():
    jac = np.array([[1.0, 0.0, 2.0]])
    result = gauss_newton_covariance(jac)
    assert result.rank == 1
    assert np.all(np.isinf(result.stderr))  # one row cannot separate x0 from x2; x1 unseen


def test_prior_precision_closed_form():
    _, design, sigma = _line_fit(2)
    prior = np.diag([1.0 / 0.5**2, 1.0 / 200.0**2])
    result = gauss_newton_covariance(design, residual_std=sigma, prior_precision=prior)
    expected = np.linalg.inv(design.T @ design / sigma**2 + prior)
    np.testing.assert_allclose(result.covariance, expected, rtol=1e-9)
    # a prior alone: its own inverse
    alone = gauss_newton_covariance(np.zeros((0, 2)), prior_precision=prior)
    np.testing.assert_allclose(alone.covariance, np.linalg.inv(prior), rtol=1e-12)
    with pytest.raises(ValueError, match="prior_precision must be"):
        gauss_newton_covariance(design, prior_precision=np.eye(3))


def test_information_rows_square_root_across_units():
    fisher = np.array([[4e14, 3e7], [3e7, 9.0]])  # eta in s against a dimensionless constant
    rows = information_rows(fisher)
    np.testing.assert_allclose(rows.T @ rows, fisher, rtol=1e-10)


def test_jax_path_under_jit_and_vmap_matches_numpy():
    _, design, sigma = _line_fit(3)
    batch = jnp.stack([jnp.asarray(design), 2.0 * jnp.asarray(design)])
    stderr = jax.jit(jax.vmap(lambda j: gauss_newton_covariance(j, residual_std=sigma).stderr))(batch)
    expected = gauss_newton_covariance(design, residual_std=sigma).stderr
    np.testing.assert_allclose(np.asarray(stderr), [expected, expected / 2.0], rtol=1e-10)
