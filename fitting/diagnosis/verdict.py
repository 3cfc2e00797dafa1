"""The verdict on candidates: the noise band (the alarm's too), the tests a candidate must pass,
naming one, and the conclusion."""

from __future__ import annotations

import dataclasses
import math

from .evaluator import _status
from .locate import describe
from .protocol import FEW_STRENGTHS, LOCAL_BAND_SIGMA, NOISE_BAND_SIGMA, PRACTICAL_GAP
from .results import CandidateResult, Step


class _Verdict:
    """The decisions of `_Workflow` (its state: `fitting.diagnosis.workflow`)."""

    def dof_of(self, effects) -> int:
        return self.n - len(self.search.columns(effects))

    def band(self, dof) -> float:
        """The noise band of the chi^2 excess: NOISE_BAND_SIGMA standard deviations of the
        chi^2 of a model that holds, from the samples' noise (2 dof) and from the noise
        levels' own estimates (`_Search.noise_estimate_variance`)."""
        return NOISE_BAND_SIGMA * math.sqrt(2 * dof + self.search.noise_estimate_variance)

    def at_noise(self, chi2: float, dof: int, location: dict | None) -> bool:
        """Whether a fit's misfit is at the noise level: its chi^2 excess within the band, and
        (where its residual breakdown `location` is given) no channel x window cell more than
        `LOCAL_BAND_SIGMA` noise units above the noise."""
        local = max((c["excess_sigma"] for c in (location or {}).get("worst", [])), default=0.0)
        return chi2 - dof <= self.band(dof) and local <= LOCAL_BAND_SIGMA

    def score_reaches_noise(self, name: str, score: float) -> bool:
        """Whether candidate `name`'s screening score (the chi^2 its linearised or secant step
        removes) would leave a chi^2 excess within the noise band of the model with it."""
        dof_c = self.dof_of(self.accepted + [name])
        return self.chi2 - score - dof_c <= self.band(dof_c)

    def explains_to_noise(self, candidate: CandidateResult) -> bool:
        dof_c = self.dof_of(self.accepted + [candidate.effect])
        return candidate.chi2 - dof_c <= self.band(dof_c)

    def _verdict(self, c: CandidateResult, excess, dof, at_noise) -> CandidateResult:
        """`c` with `passed`, `reason` and `heldout_gain` set by the checks of `heldout_check`."""
        if at_noise:
            return dataclasses.replace(c, reason="the misfit is already at the noise level")
        if c.bic_gain <= 0:
            return dataclasses.replace(c, reason=f"delta chi^2 {c.delta_chi2:.4g} below the BIC penalty "
                                                 f"{c.n_parameters * self.penalty:.4g}")
        if c.share_of_excess < self.min_share:
            return dataclasses.replace(c, reason=f"removes only {100 * c.share_of_excess:.3g} % of the excess "
                                                 f"misfit (needs {100 * self.min_share:.3g} %)")
        many = c.n_parameters > FEW_STRENGTHS
        if many and excess < PRACTICAL_GAP * dof:
            return dataclasses.replace(c, reason=(
                f"possible, not needed: {c.n_parameters} strengths for a misfit of {excess / dof:.3g} per "
                f"degree of freedom above the noise (named from {PRACTICAL_GAP:g} on)"))
        heldout_gain = None
        search = self.search
        if search.folds:
            search.log(f"held-out check of {c.effect}")
            heldout_gain = (self.heldout(self.x, self.accepted)
                            - self.heldout(c.x, self.accepted + [c.effect]))
            margin = c.n_parameters * (self.penalty if many else 1.0)
            if heldout_gain <= margin:
                return dataclasses.replace(c, heldout_gain=heldout_gain, reason=(
                    f"held-out chi^2 improves by only {heldout_gain:.4g} (needs {margin:.4g})"))
        return dataclasses.replace(c, heldout_gain=heldout_gain, passed=True,
                                   reason="passes BIC, practical-significance and held-out checks")

    @staticmethod
    def _with_status(c: CandidateResult) -> CandidateResult:
        """`c` with its reason saying so when its refit did not converge: it is judged at its
        last iterate, whose chi^2 is above the optimum's (the fit only descends), so its gain
        is a lower bound: a pass stands, a rejection may not."""
        if c.converged is not False:
            return c
        verdict = "named on a lower bound of its gain" if c.passed else "the rejection may not stand"
        return dataclasses.replace(c, reason=f"{c.reason}; its refit did not converge within {c.steps} steps "
                                             f"({verdict})")

    def name(self, passed, results, location):
        """Add the candidate of `passed` with the largest held-out gain to the model, refit."""
        search = self.search
        winner = max(passed, key=lambda c: (c.heldout_gain if c.heldout_gain is not None else c.delta_chi2))
        effects = self.accepted + [winner.effect]
        result = search.fit(winner.x, effects, max_steps=20)
        x_new, chi2_new = result.x, result.chi2
        dof, dof_new = self.dof_of(self.accepted), self.dof_of(effects)
        self.steps.append(Step(
            effect=winner.effect,
            gap_before=self.chi2 / dof, gap_after=chi2_new / dof_new,
            chi2_before=self.chi2, chi2_after=chi2_new, dof_before=dof, dof_after=dof_new,
            values=winner.values, stderr=winner.stderr, candidates=results,
            location_before=location, location_after=self.locate(x_new), x_before=self.x, x_after=x_new,
            status=_status(result),
        ))
        search.log(f"named {winner.effect}: chi^2/dof {self.chi2 / dof:.4g} -> {chi2_new / dof_new:.4g}")
        self.accepted = effects
        self.x, self.chi2, self.status = x_new, chi2_new, _status(result)

    # --- 7. report ----------------------------------------------------------------------------------
    def unconverged_fits(self, named) -> list[str]:
        """The fits the result rests on that reached no optimum (`fitting.fit`'s test), in
        words: each named effect's candidate refit (what its verdict judged) and the fit that
        added it, and the final fit (the values reported)."""
        notes = []
        final_is_last = bool(self.steps) and not self.dropped
        for k, step in enumerate(self.steps):
            if step.effect not in named:
                continue
            winner = next((c for c in step.candidates if c.effect == step.effect), None)
            if winner is not None and winner.converged is False:
                notes.append(f"the refit of candidate {step.effect} ({winner.steps} steps)")
            if step.status.get("converged") is False:
                final = " (the final fit)" if final_is_last and k == len(self.steps) - 1 else ""
                notes.append(f"the fit with {step.effect} added{final} ({step.status['steps']} steps)")
        if not self.status["converged"] and not (final_is_last and self.steps[-1].status.get("converged") is False):
            notes.append(f"the final fit ({self.status['steps']} steps)")
        return notes

    def conclusion(self, named, final_location) -> tuple[bool, str, list]:
        """(misspecification alarm, the conclusion in words, where the final misfit lies)."""
        search, x, chi2 = self.search, self.x, self.chi2
        dof = self.dof_of(self.accepted)
        excess = chi2 - dof
        alarm = not self.at_noise(chi2, dof, final_location)
        where = describe(final_location)
        if named:
            text = f"Named missing effect(s), in order: {', '.join(named)}."
            for name in named:
                text += search.interpret(name, x, self.accepted, chi2)
        else:
            text = "No missing effect detected: no candidate passes the tests."
        for swap in self.exchanged:
            text += (f" {swap['in']} was put in place of {swap['out']} by the exchange check (chi^2 "
                     f"{swap['chi2_before']:.6g} -> {swap['chi2_after']:.6g}, BIC gain {swap['bic_gain']:.4g}).")
        if "rotational_friction" in named:
            text += (" rotational_friction is a uniform scale of the contact stiffness, kappa* = (1+mu*) kappa: "
                     "in this form it cannot be told apart from an error in the beads' Young's modulus.")
        if alarm:
            local = max((c["excess_sigma"] for c in final_location.get("worst", [])), default=0.0)
            text += (f" MISSPECIFICATION ALARM: the final misfit is still above the noise level ("
                     f"{NOISE_BAND_SIGMA * excess / self.band(dof):.1f} noise units in all, "
                     f"chi^2/dof = {chi2 / dof:.4g}; "
                     f"{local:.1f} in the worst channel x window cell); the library does not explain "
                     f"it. Largest gaps: {'; '.join(where)}.")
        else:
            text += f" The final misfit is at the noise level (chi^2/dof = {chi2 / dof:.4g})."
        unconverged = self.unconverged_fits(named)
        if unconverged:
            text += (f" NOT CONVERGED: {'; '.join(unconverged)} reached no optimum; the values reported are "
                     "their last iterate's, and an effect named on such a refit stands on a lower bound of its "
                     "gain (rerun with the named effects in --model to refit them).")
        rejected = [c.effect for c in self.last_candidates if c.converged is False]
        if rejected:
            text += (f" Refits that did not converge, judged at their last iterate (their rejection may not "
                     f"stand): {', '.join(rejected)}.")
        if self.not_separable:
            text += (f" Not separable from the free parameters and the named effects: "
                     f"{', '.join(sorted(self.not_separable))} (e.g. a uniform stiffness scale while both striker "
                     "velocity and gain are free, or once contact_exponent, which fits the stiffness too, is named).")
        return alarm, text, where
