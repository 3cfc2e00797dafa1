"""The data-derived start's non-negative least squares (`fitting.start._nonnegative_least_squares`)
against scipy's NNLS on random two-column problems, both signs of the truth."""

import numpy as np
from scipy.optimize import nnls

from fitting.start import _nonnegative_least_squares


def test_two_column_nnls_equals_scipys():
    rng = np.random.default_rng(12)
    active = set()
    for _ in range(400):
        rows = rng.normal(size=(rng.integers(2, 9), 2)) * rng.uniform(0.1, 10, size=2)
        rhs = rows @ rng.normal(size=2) + 0.3 * rng.normal(size=rows.shape[0])
        ours = _nonnegative_least_squares(rows, rhs)
        theirs, _ = nnls(rows, rhs)
        np.testing.assert_allclose(np.sum((rows @ ours - rhs) ** 2), np.sum((rows @ theirs - rhs) ** 2),
                                   rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(ours, theirs, rtol=1e-7, atol=1e-10)
        active.add(tuple(ours > 0))
    assert active == {(True, True), (True, False), (False, True), (False, False)}
