"""The held-out check: two-fold cross-validation over files by one damped Gauss-Newton step
from the fit to all files."""

from __future__ import annotations

import math

import numpy as np


class _HeldOut:
    """The held-out chi^2 of `_Search`."""

    # --- held-out check ---------------------------------------------------------------------------
    def heldout_chi2(self, x_fit, effects) -> float | None:
        """Summed held-out chi^2 of a model over the two folds (see module docstring).

        Approximate cross-validation, one Levenberg-Marquardt step from the fit to all
        files `x_fit`: the global parameters are refitted on the training fold's residuals
        with every training file's nuisances profiled out, and the held-out files'
        residuals at those globals are taken with their own nuisances profiled out. The
        step is the Gauss-Newton one unless the model's own residuals say it leaves the
        region where it is linear (a nearly flat direction of 21 bead radii can ask for a
        shift of 2000 % to gain a chi^2 of 100): it is then damped until the training
        fold's chi^2 no longer rises. Costs one Jacobian (usually already computed for the
        standard errors) and a few residual evaluations.
        """
        if len(self.folds) < 2:
            return None
        cols = self.columns(effects)
        r, jac = self.evaluate(x_fit, cols)
        global_cols = [c for c in cols if self.problem.instances[c].experiment is None]

        nuisance_bases = [np.linalg.qr(jac[np.ix_(rows, columns)])[0] if columns else None
                          for rows, columns in zip(self.file_rows, self.file_columns)]

        def profiled(e, block):
            """`block` (rows of file e) with file e's nuisance directions projected out."""
            q = nuisance_bases[e]
            return block if q is None else block - q @ (q.T @ block)

        def profiled_chi2(residuals, files):
            return sum(float(np.sum(profiled(e, residuals[self.file_rows[e]]) ** 2)) for e in files)

        total = 0.0
        for held in self.folds:
            train = [e for e in range(len(self.file_rows)) if e not in held]
            x_train = x_fit
            if global_cols:
                a = np.vstack([profiled(e, jac[np.ix_(self.file_rows[e], global_cols)]) for e in train])
                b = np.concatenate([profiled(e, r[self.file_rows[e]]) for e in train])
                x_train = self._damped_step(x_fit, global_cols, a, b, lambda x, files=train: profiled_chi2(x, files))
            moved = r if x_train is x_fit else self.evaluate.residuals(x_train)
            total += profiled_chi2(moved, held)
        return total

    def _damped_step(self, x_fit, columns, a, b, chi2_of):
        """`x_fit` moved on `columns` by the least-damped Gauss-Newton step of the linear
        model `a dx + b` (Marquardt scaling) whose actual chi^2, `chi2_of(residuals)`, is
        not above the linear model's at rest, `b @ b`; `x_fit` itself when none is."""
        at_rest = float(b @ b)
        scale = np.sqrt(np.maximum(np.sum(a * a, axis=0), np.finfo(float).tiny))
        for damping in (0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0):
            lhs = np.vstack([a, np.diag(math.sqrt(damping) * scale)])
            shift = -np.linalg.lstsq(lhs, np.concatenate([b, np.zeros(len(columns))]), rcond=None)[0]
            trial = np.array(x_fit, dtype=float)
            trial[columns] = np.clip(trial[columns] + shift, self.lower[columns], self.upper[columns])
            chi2 = chi2_of(self.evaluate.residuals(trial))
            if math.isfinite(chi2) and chi2 <= at_rest:
                return trial
        return x_fit
