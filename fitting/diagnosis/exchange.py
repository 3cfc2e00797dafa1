"""The exchange check: a named effect put out for a rival of its round when the rival, in its
place, explains the data better.

The rounds add one effect at a time, each the best of its round given the effects before it.
That greedy order can lock in an effect that mimicked part of a misfit several effects share:
measured on a 15-bead brass chain hiding a soft wall and viscous damping (independent Verlet
data), the first round's 15 per-bead radii fitted 0.8 % lower than the wall's one modulus
(dispersion at the last beads mimics a soft wall, and with viscous damping also missing
neither is near the noise); once the radii were in, the wall removed 4 % of what was left and
was never named, and the diagnosis ended with the alarm on.

So when the model the rounds and the backward check leave still misfits (the misspecification
alarm's own test, `_Verdict.at_noise`), each named effect is refitted with, in its place, each
candidate refitted in the round that named it (its rivals: `max_refits` of them at most). An
exchange is taken when it gains by the criterion every naming used, BIC (the chi^2 it removes
beyond ln(n) per extra strength, or plus ln(n) per strength it saves), and, where there are
held-out folds, lowers the held-out chi^2 too. The best such exchange is taken, the rounds
resume, and the check repeats until no exchange gains (each strictly lowers BIC, so it ends).
No threshold is chosen here; the rule is the rounds' own, applied to a swap instead of an
addition. A model at the noise level is not checked: the rounds' parsimony rules already chose
between candidates that reach it.
"""

from __future__ import annotations

import math

from .evaluator import _status
from .results import CandidateResult, Step


class _Exchange:
    """The exchange check of `_Workflow` (its state: `fitting.diagnosis.workflow`)."""

    def exchange_check(self) -> bool:
        """Try the exchanges (module docstring); take the best that gains; whether one was taken."""
        location = self.locate()
        if self.at_noise(self.chi2, self.dof_of(self.accepted), location):
            return False
        search = self.search
        tried = {(e["out"], e["in"]) for e in self.exchanged}
        trials = [(step, rival) for step in self.steps if step.effect in self.named_effects
                  for rival in sorted(step.candidates, key=lambda c: c.chi2)
                  if rival.effect not in self.accepted and rival.separable and rival.x is not None
                  and math.isfinite(rival.chi2) and (step.effect, rival.effect) not in tried]
        if not trials:
            return False
        search.log("exchange check: " + ", ".join(f"{rival.effect} for {step.effect}" for step, rival in trials))
        best = None
        for step, rival in trials:
            trial = self._exchange(step.effect, rival)
            if trial["bic_gain"] > 0 and (trial["heldout_gain"] is None or trial["heldout_gain"] > 0) \
                    and (best is None or trial["bic_gain"] > best["bic_gain"]):
                best = trial
        if best is None:
            search.log("exchange check: no exchange gains")
            return False
        self._take(best, location)
        return True

    def _exchange(self, out: str, rival: CandidateResult) -> dict:
        """The model with `rival` in place of `out`, refitted from the current fit with `out`
        off and `rival`'s strengths where its round's refit had them."""
        search = self.search
        effects = [e for e in self.accepted if e != out] + [rival.effect]
        x_start = self.x.copy()
        for c in search.effect_columns[out]:
            x_start[c] = 0.0
        for c in search.effect_columns[rival.effect]:
            x_start[c] = rival.x[c]
        fitted = search.refit([x_start], effects, rival.effect)
        saved = len(search.effect_columns[out]) - len(search.effect_columns[rival.effect])
        bic_gain = (self.chi2 - fitted.chi2) + saved * self.penalty
        heldout_gain = None
        if search.folds and bic_gain > 0:
            heldout_gain = self.heldout(self.x, self.accepted) - self.heldout(fitted.x, effects)
        search.log(f"exchange {rival.effect} for {out}: chi^2 {self.chi2:.6g} -> {fitted.chi2:.6g}, "
                   f"BIC gain {bic_gain:.4g}" + ("" if heldout_gain is None else f", held-out gain {heldout_gain:.4g}"))
        return {"out": out, "in": rival.effect, "effects": effects, "fit": fitted, "chi2_before": self.chi2,
                "chi2_after": fitted.chi2, "bic_gain": bic_gain, "heldout_gain": heldout_gain,
                "converged": fitted.converged, "steps": fitted.steps}

    def _take(self, trial: dict, location: dict):
        """Put the exchange `trial` into the model: a `Step` naming the rival (`replaces` the
        effect put out) and a record in `exchanged`."""
        search = self.search
        fitted, name, effects = trial["fit"], trial["in"], trial["effects"]
        # the refit may hold per-bead strengths named before (`_Search.held_for`); the model
        # taken is refitted with everything free, as a named effect's is (`_Verdict.name`)
        final = search.fit(fitted.x, effects, max_steps=20)
        cols = search.effect_columns[name]
        all_cols = search.columns(effects)
        err = search.stderr(fitted.x, all_cols, fitted.chi2)
        values = {search.labels[c]: float(fitted.x[c]) for c in cols}
        stderr = {search.labels[c]: float(err[all_cols.index(c)]) for c in cols}
        dof, dof_new = self.dof_of(self.accepted), self.dof_of(effects)
        candidate = CandidateResult(
            effect=name, n_parameters=len(cols), score_chi2=math.nan, chi2=fitted.chi2,
            delta_chi2=self.chi2 - fitted.chi2, bic_gain=trial["bic_gain"], heldout_gain=trial["heldout_gain"],
            values=values, stderr=stderr, passed=True, x=fitted.x, converged=fitted.converged, steps=fitted.steps,
            reason=f"in place of {trial['out']}: gains by BIC" + ("" if trial["heldout_gain"] is None
                                                                  else " and on the held-out folds"))
        self.steps.append(Step(
            effect=name, gap_before=self.chi2 / dof, gap_after=final.chi2 / dof_new,
            chi2_before=self.chi2, chi2_after=final.chi2, dof_before=dof, dof_after=dof_new,
            values=values, stderr=stderr, candidates=[candidate], location_before=location,
            location_after=self.locate(final.x), x_before=self.x, x_after=final.x,
            status=_status(final), replaces=trial["out"]))
        search.log(f"exchanged: {name} in place of {trial['out']}: chi^2/dof {self.chi2 / dof:.4g} -> "
                   f"{final.chi2 / dof_new:.4g}")
        self.exchanged.append({key: trial[key] for key in ("out", "in", "chi2_before", "chi2_after", "bic_gain",
                                                           "heldout_gain", "converged", "steps")})
        self.accepted = effects
        self.x, self.chi2, self.status = final.x, final.chi2, _status(final)
