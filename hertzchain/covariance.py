"""The Gauss-Newton covariance of a least-squares fit: one routine for every fit in both packages.

For residuals $r(x)$ with Jacobian $J$ at the optimum, each residual of standard deviation
$\\sigma$, and an optional Gaussian prior of precision $P$ on $x$, the linearised covariance
of the estimate is

$$\\Sigma = \\left(J^TJ/\\sigma^2 + P\\right)^{+},$$

which for a linear model without a prior is the textbook $\\sigma^2 (J^TJ)^{-1}$. The
pseudo-inverse is taken by an SVD of the stacked rows $[J/\\sigma;\\ P^{1/2}]$ with each
column normalised to unit length (so that parameters of very different units are compared
fairly): a singular value below `rcond` times the largest is a direction the data cannot
see. It is dropped from the inverse, and every parameter taking part in it (a component
above `PARTICIPATION` of its normalised singular vector) or whose column is zero gets an
infinite standard error. `GaussNewtonCovariance` reports the rank and the condition number
of what was kept.

It works on NumPy arrays and, under `jit` and `vmap`, on JAX arrays (the cos^6 pulse fit).
`fitting.uncertainty` builds the fit's choice of $\\sigma$ (stated noise, residuals,
Newey-West) and its identifiability messages on it; `hertzchain` never imports `fitting`.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# Singular value (relative to the largest, column-normalised) below which a direction is
# taken as one the data cannot constrain.
DEGENERATE_RATIO = 1e-6
# Component of a normalised singular vector that names a parameter as taking part in it.
PARTICIPATION = 0.1


class GaussNewtonCovariance(NamedTuple):
    """The covariance of a least-squares estimate and how well it is determined.

    **Fields** (NumPy arrays, or JAX arrays when the Jacobian was one):

    - `covariance`: (p, p) $(J^TJ/\\sigma^2 + P)^+$, in the squared units of the parameters.
    - `stderr`: (p,) square roots of its diagonal; infinite for a parameter the data cannot
      constrain (see the module docstring).
    - `singular_values`: (p,) of the column-normalised stacked rows, descending.
    - `directions`: (p, p) the right singular vectors as rows, in normalised coordinates.
    - `kept`: (p,) bool, which singular values the inverse kept (relative value > `rcond`).
    - `rank`: how many were kept.
    - `condition`: the largest over the smallest kept singular value (1 for orthogonal
      columns of equal weight; `inf` when none was kept).
    - `column_norms`: (p,) the norms the columns were divided by (their units: residual per
      parameter unit).
    """

    covariance: Any
    stderr: Any
    singular_values: Any
    directions: Any
    kept: Any
    rank: Any
    condition: Any
    column_norms: Any


def _is_jax(a) -> bool:
    return isinstance(a, jax.Array)


def information_rows(information):
    """(p, p) rows $R$ with $R^TR$ = `information` (a symmetric positive semi-definite matrix,
    e.g. a Fisher matrix or a prior's precision), stacked under a Jacobian they add that
    information. The symmetric square root of the matrix scaled to a unit diagonal (so that
    parameters of very different units keep their digits), negative eigenvalues of rounding
    clipped to 0."""
    xp = jnp if _is_jax(information) else np
    information = xp.asarray(information, dtype=float)
    diag = xp.diag(information)
    scale = xp.sqrt(xp.where(diag > 0, diag, 1.0))
    normalised = information / xp.outer(scale, scale)
    values, vectors = xp.linalg.eigh(0.5 * (normalised + normalised.T))
    return ((vectors * xp.sqrt(xp.clip(values, 0.0, None))) @ vectors.T) * scale


def gauss_newton_covariance(jacobian, *, residual_std=1.0, prior_precision=None,
                            rcond: float = DEGENERATE_RATIO) -> GaussNewtonCovariance:
    """The Gauss-Newton covariance $(J^TJ/\\sigma^2 + P)^+$ (module docstring).

    **Arguments:**

    - `jacobian`: (n, p) Jacobian of the residuals with respect to the parameters, in
      residual units per parameter unit (n may be 0 when `prior_precision` carries all).
    - `residual_std`: $\\sigma$, the standard deviation of each residual (1 for whitened
      residuals; $\\sqrt{\\chi^2/\\mathrm{dof}}$ to estimate it from the fit).
    - `prior_precision`: (p, p) precision $P$ of a Gaussian prior on the parameters, in
      inverse squared parameter units, or None.
    - `rcond`: relative singular value below which a direction is dropped.

    **Returns:** `GaussNewtonCovariance`.
    """
    xp = jnp if _is_jax(jacobian) or _is_jax(residual_std) else np
    rows = xp.asarray(jacobian, dtype=float)
    if rows.ndim != 2:
        raise ValueError(f"jacobian must be (n, p), got shape {rows.shape}.")
    p = rows.shape[1]
    # without a prior sigma scales the result (so that sigma = 0 or NaN, a fit without degrees
    # of freedom, gives a zero or NaN covariance rather than failing the SVD)
    variance = residual_std**2 if prior_precision is None else 1.0
    if prior_precision is not None:
        rows = rows / residual_std
        if np.shape(prior_precision) != (p, p):
            raise ValueError(f"prior_precision must be ({p}, {p}) for a Jacobian of {p} columns, "
                             f"got shape {np.shape(prior_precision)}.")
        rows = xp.concatenate([rows, information_rows(xp.asarray(prior_precision, dtype=float))])
    if rows.shape[0] < p:  # fewer rows than parameters: zero rows give the unseen directions
        rows = xp.concatenate([rows, xp.zeros((p - rows.shape[0], p))])
    norms = xp.linalg.norm(rows, axis=0)
    safe = xp.where(norms > 0, norms, 1.0)
    _, singular, vt = xp.linalg.svd(rows / safe, full_matrices=False)
    top = xp.where(singular[0] > 0, singular[0], 1.0) if p else 1.0
    kept = singular / top > rcond
    inverse = xp.where(kept, 1.0 / xp.where(kept, singular, 1.0) ** 2, 0.0)
    covariance = variance * ((vt.T * inverse) @ vt) / xp.outer(safe, safe)
    unseen = xp.any((~kept)[:, None] & (xp.abs(vt) > PARTICIPATION), axis=0) | (norms == 0)
    stderr = xp.where(unseen, xp.inf, xp.sqrt(xp.clip(xp.diag(covariance), 0.0, None)))
    rank = xp.sum(kept)
    smallest = xp.min(xp.where(kept, singular, xp.inf)) if p else xp.inf
    condition = xp.where(rank > 0, singular[0] / smallest, xp.inf) if p else xp.inf
    if xp is np:
        rank, condition = int(rank), float(condition)
    return GaussNewtonCovariance(covariance, stderr, singular, vt, kept, rank, condition, norms)
