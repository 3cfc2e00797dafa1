"""The diagnosis's result assembled from its rounds (`Diagnosis`)."""

from __future__ import annotations

import math
import time

from .protocol import NOISE_BAND_SIGMA, parse_model
from .results import Diagnosis


class _Report:
    """The report of `_Workflow`."""

    def summary(self, xv, chi, effects, status) -> dict:
        search = self.search
        d = self.dof_of(effects)
        cols = search.columns(effects)
        err = search.stderr(xv, cols, chi)
        return {
            "effects": list(effects), "chi2": chi, "dof": d, "gap": chi / d, **status,
            "excess_sigma": (chi - d) / math.sqrt(2 * d),
            "values": {search.labels[c]: float(xv[c]) for c in cols},
            "stderr": {search.labels[c]: float(err[i]) for i, c in enumerate(cols)},
        }

    def report(self, settings: dict, began: float) -> Diagnosis:
        """The `Diagnosis`: named effects, base and final fits, alarm and conclusion;
        `settings`: the arguments of `diagnose` it records (free, nuisances, max_effects,
        steps_per_contact)."""
        search = self.search
        named = self.named_effects
        final_location = self.locate()
        alarm, text, where = self.conclusion(named, final_location)
        unconverged = self.unconverged_fits(named)
        base_summary = self.summary(self.x_base, self.chi2_base, parse_model(self.model, search.n_beads),
                                    self.status_base)
        base_summary["location"] = (self.steps[0].location_before if self.steps else self.locate(self.x_base))
        final_summary = self.summary(self.x, self.chi2, self.accepted, self.status)
        final_summary["location"] = final_location
        final_summary["where"] = where
        return Diagnosis(
            missing_effects=named,
            steps=self.steps,
            base_fit=base_summary,
            final=final_summary,
            last_candidates=self.last_candidates,
            not_separable=sorted(self.not_separable),
            indistinguishable=self.pairs_seen,
            dropped_in_backward_check=self.dropped,
            misspecification=bool(alarm),
            conclusion=text,
            unconverged=unconverged,
            settings={
                "model": self.model, "free": settings["free"], "nuisances": settings["nuisances"],
                "candidates": search.candidates, "left_out": search.skipped, "max_effects": settings["max_effects"],
                "min_share": self.min_share, "noise_band_sigma": NOISE_BAND_SIGMA,
                "chi2_variance_from_noise_estimates": search.noise_estimate_variance,
                "bic_penalty_per_parameter": self.penalty, "steps_per_contact": settings["steps_per_contact"],
                "folds": [[search.problem.experiments[e].label for e in f] for f in search.folds],
            },
            problem=search.problem,
            predictions=search.evaluate.predictions,
            x_base=self.x_base,
            x_final=self.x,
            elapsed_s=time.perf_counter() - began,
            evaluations=search.evaluate.calls,
            evaluation_seconds=search.evaluate.seconds,
            residual_evaluations=search.evaluate.residual_calls,
            exchanged=self.exchanged,
        )
