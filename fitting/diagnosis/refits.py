"""Fits of a diagnosis: least squares on chosen columns and rows, refits of a candidate
from several starts (with time-window continuation), and standard errors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..fit import OPTIMUM_TOLERANCE, LeastSquares
from ..uncertainty import covariance_choice, covariance_from_jacobian
from .evaluator import _Bounded, _rank
from .protocol import FEW_STRENGTHS, WINDOW_FRACTIONS, WINDOW_MAX_STEPS, WINDOW_TOLERANCE


class _Refits:
    """The fits of `_Search` (its state: `fitting.diagnosis.search`)."""

    def fit(self, x_start, effects, *, rows=None, columns=None, max_steps=40,
            tolerance=OPTIMUM_TOLERANCE) -> LeastSquares:
        """Least squares (`fitting.fit.least_squares`, with `fitting.fit`'s test of an optimum
        to `tolerance`) of the columns of `effects` (or `columns`) on the residuals `rows`
        (default all) from `x_start`; the end point clipped to the bounds. Its `chi2` is on
        `rows`; `converged` and `steps` say how it ended."""
        cols = self.columns(effects) if columns is None else list(columns)
        weights = None
        if rows is not None:
            weights = np.zeros(self.n)
            weights[rows] = 1.0
        # read at each call: replacing fitting.diagnosis.least_squares reaches every fit
        from . import least_squares

        result = least_squares(_Bounded(self.evaluate, self.lower, self.upper), x_start, cols,
                               weights=weights, max_steps=max_steps, tolerance=tolerance,
                               bounds=(self.lower, self.upper))
        return dataclasses.replace(result, x=np.clip(result.x, self.lower, self.upper))

    def _acts(self, x, strengths) -> bool:
        """Whether a candidate's `strengths` change the model at `x`: its residuals differ
        from those with the strengths at 0 (off) by more than round-off (1e-9 of their norm)."""
        off = np.array(x, dtype=float)
        off[strengths] = 0.0
        on_r, off_r = self.evaluate.residuals(x), self.evaluate.residuals(off)
        return float(np.linalg.norm(on_r - off_r)) > 1e-9 * float(np.linalg.norm(off_r))

    def fresh(self, x) -> np.ndarray:
        """`x` with every per-file nuisance back at its start value (header velocity, zero
        trigger offset, unit gain); physical parameters and effect strengths kept."""
        s = np.array(x, dtype=float)
        s[self.nuisance_columns] = self.x0[self.nuisance_columns]
        return s

    def refit(self, starts, effects, name: str, *, max_steps=20):
        """Fit with candidate `name` added, from the best of `starts`.

        From each start, the candidate's strengths are first fitted alone, with the other
        parameters held either where the current fit has them or at fresh nuisances
        (`fresh`); from the lowest of these ends everything is fitted together. Fresh nuisances
        matter because a model that lacks an effect pays for it with its nuisances: without
        a softer wall and damping, a base fit lowers the striker velocities by tens of
        percent and moves the trigger to its bound, a basin from which the candidate's own
        optimum cannot be reached. Strengths first matter because, freed together while
        the strength is far from its value, a file's nuisances can run to a bound where the
        record no longer depends on them (a striker velocity at its floor, whose pulse never
        arrives) and stay there: measured on a preloaded chain read by piezo sensors, a
        joint refit stopped at 914 times the noise, this one at the noise level.

        Per-bead strengths (`bead_dispersion`) are fitted by time-window continuation: on
        records cut at growing fractions of their length first, so early pulses fix the
        first beads before later, multiply scattered waves come in (from zero, a fit of all
        radii on whole records stops in a local minimum shifted by a fraction of a pulse:
        the cycle skipping of wave inversion). Its starts are compared after the first
        window and only the better one is continued (each Jacobian costs one tangent per
        bead)."""
        if name == "bead_dispersion":
            starts = list(starts) + [self.fresh(starts[0])]

            def window_fit(x, fraction):
                rows = np.nonzero(self.row_time_fraction <= fraction)[0]
                return self.fit(x, effects, rows=rows, max_steps=WINDOW_MAX_STEPS, tolerance=WINDOW_TOLERANCE)

            x = min((window_fit(x, WINDOW_FRACTIONS[0]) for x in starts), key=_rank).x
            for fraction in WINDOW_FRACTIONS[1:]:
                x = window_fit(x, fraction).x
            # the windows can lead away from the whole record's optimum (measured: 11-bit data
            # of the paper's chain, whole-record chi^2 up 70 %): then the whole record is
            # also fitted from the best start directly
            chi2_of = lambda point: float(np.sum(self.evaluate.residuals(point) ** 2))
            starts = [x] if chi2_of(x) <= chi2_of(starts[0]) else [x, starts[0]]
        else:
            # strengths alone cost a tangent each; everything free costs one per free parameter
            # (a per-bead effect already named: one per bead), so only the best is continued
            strengths = self.effect_columns[name]
            ends = sorted((self.fit(x, effects, columns=strengths, max_steps=max_steps)
                           for s in starts for x in (s, self.fresh(s))), key=_rank)
            starts = [ends[0].x]
            # A threshold effect's strengths, fitted alone with the nuisances the current fit
            # bent to mimic it, can walk back to where the effect does nothing (a yield force
            # above every force: the base model, flat there), and from fresh nuisances end
            # worse: measured on a 10-bead chain whose fastest shot yields (the base fit lowered
            # its striker velocity 10 %), the best end had the base's chi^2 to 1e-12 and the
            # joint refit never moved. Then the best end where the effect acts is continued too.
            if not self._acts(ends[0].x, strengths):
                acting = [end for end in ends[1:] if math.isfinite(end.chi2) and self._acts(end.x, strengths)]
                starts += [acting[0].x] if acting else []
        # per-bead strengths named before stay where they are (`held_for`)
        columns = [c for c in self.columns(effects) if c not in self.held_for(name, effects)]
        # a fit that ended on a non-finite chi^2 never counts as the best
        return min((self.fit(x, effects, columns=columns, max_steps=max_steps) for x in starts), key=_rank)

    def held_for(self, name: str, effects) -> set[int]:
        """Columns a refit of candidate `name` holds: the strengths of the effects of
        `effects` named before it that have more than `FEW_STRENGTHS` of them (per-bead
        radii). Freed, each costs a tangent per step of every candidate's refit (15-21 of
        the 25-35 a refit carries); held at their fit, a candidate's delta chi^2 can only be
        underestimated (a conservative check), and the model it wins is refitted with
        everything free when it is named (`_Workflow.name`)."""
        return {c for effect in effects if effect != name and len(self.effect_columns[effect]) > FEW_STRENGTHS
                for c in self.effect_columns[effect]}

    def stderr(self, x, columns, chi2) -> np.ndarray:
        """Standard errors of `columns` at `x` (chi^2 `chi2`): `fitting.uncertainty`'s
        covariance, scaled as `fitting.fit` scales it (`covariance_choice`)."""
        _, jac = self.evaluate(x, columns)
        dof = self.problem.n_fitted - len(columns)
        scale, _ = covariance_choice("auto", chi2, dof)
        labels = [self.labels[c] for c in columns]
        return covariance_from_jacobian(jac[:, columns], labels, chi2=chi2, dof=dof, scale=scale).stderr
