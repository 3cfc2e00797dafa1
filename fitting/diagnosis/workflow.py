"""The diagnosis's workflow: base fit, rounds of locate, screen, refit and verdict, the
backward check; and `diagnose`, which runs it."""

from __future__ import annotations

import math
import time

from hertzchain.progress import Progress
from hertzchain.units import counted

from .. import effects as fx
from ..data import as_experiments
from ..model import STEPS_PER_CONTACT
from ..parameters import get_spec, parse_parameter_list, public_label, resolve_name
from .assembly import _Report
from .evaluator import _status
from .exchange import _Exchange
from .locate import locate
from .protocol import MIN_SHARE, NUISANCES, DiagnosisError, parse_model
from .results import CandidateResult, Diagnosis, Step
from .search import _Search
from .verdict import _Verdict


class _Workflow(_Verdict, _Exchange, _Report):
    """The steps of one diagnosis (`diagnose`), in the order they run: `base_fit`, then per
    round `locate`, `screen`, `refit`, `heldout_check` (with the other tests a candidate must
    pass) and `name`; then `backward_check`, `exchange_check` (after an exchange, the rounds
    resume) and `report`. Holds the current model
    (`accepted`, its fit `x`, `chi2`) and what the rounds found."""

    def __init__(self, search: _Search, model: str, *, min_share: float, max_refits: int, progress: bool):
        self.search = search
        self.model = model
        self.min_share = min_share
        self.max_refits = max_refits
        self.progress = progress
        self.accepted = parse_model(model, search.n_beads)
        self.n = search.problem.n_fitted
        self.penalty = math.log(self.n)
        self.steps: list[Step] = []
        self.last_candidates: list[CandidateResult] = []
        self.not_separable: set = set()
        self.pairs_seen: list = []
        self.dropped: list = []
        self.exchanged: list = []  # the exchanges taken (`_Exchange`), in order
        self._heldout_cache: dict = {}
        self.location: dict | None = None  # the residual breakdown of the current fit

    @property
    def named_effects(self) -> list[str]:
        """The effects the steps named that are in the model now (not dropped by the backward
        check, not put out by an exchange), in the order named."""
        return [s.effect for s in self.steps if s.effect in self.accepted]

    # --- 1. base fit --------------------------------------------------------------------------------
    def base_fit(self):
        """The stated model with its nuisances (and `free` parameters) fitted."""
        search = self.search
        starts = [search.x0.copy()]
        for name in self.accepted:
            starts = [s2 for s in starts for s2 in search.start_for(name, s)][:1]
        result = search.fit(starts[0], self.accepted, max_steps=60)
        self.x, self.chi2, self.status = result.x, result.chi2, _status(result)
        search.log(f"base fit: chi^2/dof = {self.chi2 / self.dof_of(self.accepted):.4g}"
                   + ("" if result.converged else f" (no optimum within {result.steps} steps)"))
        self.x_base, self.chi2_base, self.status_base = self.x.copy(), self.chi2, self.status

    # --- 2. locate ----------------------------------------------------------------------------------
    def locate(self, x=None) -> dict:
        """Where the fit `x` (default the current one) misses: `fitting.diagnosis.locate`."""
        x = self.x if x is None else x
        evaluate = self.search.evaluate
        return locate(self.search.problem, x, evaluate.residuals(x), evaluate.predictions(x))

    # --- 3. screen ----------------------------------------------------------------------------------
    def screen(self):
        """Scores and starts of the candidates not in the model (`_Search.screen`); the
        candidates to refit: the best `max_refits` separable ones by score, whatever their
        score (a linear score at "off" misjudges effects with a threshold or a singular
        onset, see `_Search.start_for`), and any other whose score alone would bring the
        misfit into the noise band (`score_reaches_noise`). None when the misfit is at the
        noise level, and then nothing is screened (scores NaN): the screen only ranks what is
        refitted, and it costs a Jacobian of every candidate's strengths and their secants, on
        every variant of the contact law and the sensors they switch on, each variant its own
        compilation (measured on the 15-bead brass chain: a fifth of a diagnosis that names
        plasticity). Candidates found not separable in earlier rounds stay reported."""
        search = self.search
        todo = [c for c in search.candidates if c not in self.accepted]
        dof = self.dof_of(self.accepted)
        if self.at_noise(self.chi2, dof, self.location):
            search.log("the misfit is at the noise level: no candidate screened")
            return todo, {c: math.nan for c in todo}, {}, {c: True for c in todo}, []
        scores, starts, separable, pairs = search.screen(self.x, self.accepted, todo)
        search.log("screened " + ", ".join(f"{c} {scores[c]:.3g}" for c in todo))
        for pair in pairs:
            if pair not in self.pairs_seen:
                self.pairs_seen.append(pair)
        ranked = sorted((c for c in todo if separable[c]), key=lambda c: -scores[c])
        # the rank only orders the refits: a candidate whose score alone brings the misfit
        # into the noise band is what a fit of it alone would find, and is refitted whatever
        # its rank (a misfit several effects share can rank a single one below others that
        # each mimic part of it)
        reaching = [c for c in ranked[self.max_refits:] if self.score_reaches_noise(c, scores[c])]
        if reaching:
            search.log("refitted for a score that reaches the noise level: " + ", ".join(reaching))
        return todo, scores, starts, separable, ranked[:self.max_refits] + reaching

    # --- 4. refit -----------------------------------------------------------------------------------
    def refit(self, todo, scores, starts, separable, worth) -> list[CandidateResult]:
        """Refit the candidates `worth` in order of their number of strengths (`_Search.refit`),
        skipping those with more strengths once a simpler one explains the misfit to the noise
        level; one `CandidateResult` per candidate of `todo`."""
        search = self.search
        dof = self.dof_of(self.accepted)
        excess = self.chi2 - dof
        refitted: dict = {}
        bar = Progress(len(worth), "diagnose: refitting candidates",
                       since=search.report.start if search.report else None) if self.progress and worth else None
        for name in sorted(worth, key=lambda c: (len(search.effect_columns[c]), -scores[c])):
            cols = search.effect_columns[name]
            k = len(cols)
            simpler = [c for c in refitted.values() if c.n_parameters < k and self.explains_to_noise(c)]
            if simpler:
                refitted[name] = CandidateResult(
                    effect=name, n_parameters=k, score_chi2=scores[name],
                    reason=f"not refitted: {simpler[0].effect} ({counted(simpler[0].n_parameters, 'parameter')}) "
                    "already explains the misfit to the noise level")
            else:
                fitted = search.refit(starts[name], self.accepted + [name], name)
                x_c, chi2_c = fitted.x, fitted.chi2
                delta = self.chi2 - chi2_c
                all_cols = search.columns(self.accepted + [name])
                err = search.stderr(x_c, all_cols, chi2_c)
                refitted[name] = CandidateResult(
                    effect=name, n_parameters=k, score_chi2=scores[name], chi2=chi2_c, delta_chi2=delta,
                    bic_gain=delta - k * self.penalty,
                    share_of_excess=delta / excess if excess > 0 else 0.0,
                    values={search.labels[c]: float(x_c[c]) for c in cols},
                    stderr={search.labels[c]: float(err[all_cols.index(c)]) for c in cols}, x=x_c,
                    converged=fitted.converged, steps=fitted.steps)
            if bar:
                bar.advance()
        results = []
        for name in todo:
            k = len(search.effect_columns[name])
            if name in refitted:
                results.append(refitted[name])
            elif not separable[name]:
                self.not_separable.add(name)
                results.append(CandidateResult(effect=name, n_parameters=k, score_chi2=scores[name],
                                               separable=False, chi2=self.chi2,
                                               delta_chi2=0.0, bic_gain=-k * self.penalty, share_of_excess=0.0,
                                               reason="not separable from the free parameters"))
            else:
                results.append(CandidateResult(
                    effect=name, n_parameters=k, score_chi2=scores[name],
                    reason="the misfit is already at the noise level (not screened)"
                    if self.at_noise(self.chi2, dof, self.location)
                    else
                    f"score {scores[name]:.4g} not among the {self.max_refits} best, which are refitted, "
                    "and short of the noise band"))
        return results

    # --- 5. decide, with the held-out check ---------------------------------------------------------
    def heldout(self, x_fit, effects):
        """Summed held-out chi^2 of the model `effects` fitted at `x_fit` (cached per model)."""
        key = tuple(effects)
        if key not in self._heldout_cache:
            self._heldout_cache[key] = self.search.heldout_chi2(x_fit, effects)
        return self._heldout_cache[key]

    def heldout_check(self, results) -> list[CandidateResult]:
        """Judge the refitted candidates by (a) BIC, (b) practical significance (and the
        parsimony rule for many strengths) and (c) the held-out check (module docstring):
        `results` again, each refitted candidate with `passed` and a `reason` saying why it
        passed or not."""
        dof = self.dof_of(self.accepted)
        excess = self.chi2 - dof
        at_noise = self.at_noise(self.chi2, dof, self.location)
        judged = [self._verdict(c, excess, dof, at_noise) if c.separable and math.isfinite(c.delta_chi2) else c
                  for c in results]
        return judged if at_noise else [self._with_status(c) for c in judged]

    def round(self) -> bool:
        """One round: locate, screen, refit, check; names one effect (True) or none (False)."""
        location = self.location = self.locate()
        todo, scores, starts, separable, worth = self.screen()
        results = self.heldout_check(self.refit(todo, scores, starts, separable, worth))
        passed = [c for c in results if c.passed]
        if not passed:
            self.last_candidates = results
            return False
        self.name(passed, results, location)
        return True

    # --- 6. backward check --------------------------------------------------------------------------
    def backward_check(self):
        """Refit without each named effect in turn; drop any that no longer passes (a) and (b)."""
        named = self.named_effects
        if len(named) < 2:
            return
        search = self.search
        search.log("backward check of " + ", ".join(named))
        for name in named:
            others = [e for e in self.accepted if e != name]
            x_wo = self.x.copy()
            for c in search.effect_columns[name]:
                x_wo[c] = 0.0
            result = search.fit(x_wo, others)
            x_wo, chi2_wo = result.x, result.chi2
            delta = chi2_wo - self.chi2
            k = len(search.effect_columns[name])
            excess_wo = chi2_wo - self.dof_of(others)
            if delta - k * self.penalty <= 0 or (excess_wo > 0 and delta / excess_wo < self.min_share):
                self.dropped.append(name)
                self.accepted = others
                self.x, self.chi2, self.status = x_wo, chi2_wo, _status(result)


def diagnose(experiments, *, model: str = "base", free=(), nuisances=None, candidates=None,
             max_effects: int = 3, min_share: float = MIN_SHARE, steps_per_contact: int = STEPS_PER_CONTACT,
             max_refits: int = 3, progress: bool = True) -> Diagnosis:
    """Find, name and add the effects a chain model is missing (see the module docstring).

    **Arguments:**

    - `experiments`: trace file paths, `TraceFile`s or `Experiment`s (one chain length).
    - `model`: `"base"` (header's chain, no dissipation, ideal force sensors) or
      `"base+EFFECT+..."` to start with effects already in the model.
    - `free`: further parameters of the registry fitted throughout (e.g. `("C",)`); the
      candidate they stand for is then left out.
    - `nuisances`: per-file / per-channel nuisances always fitted (default None: striker
      velocity and trigger offset, `NUISANCES`; add `"gain"` for uncalibrated channels). Here
      and in `free`, a previous name (`striker_velocity`) warns once.
    - `candidates`: identifiers to consider (default: all of `fitting.effects`).
    - `max_effects`: most effects to add.
    - `min_share`: share of the remaining excess misfit a named effect must remove.
    - `steps_per_contact`: Verlet steps per shortest contact time of the model (default
      `fitting.model.STEPS_PER_CONTACT`, as every fit: coarser steps bias fitted values by
      several standard errors).
    - `max_refits`: candidates refitted per round (the best by score, whatever the score).
    - `progress`: report on stderr.

    **Returns:** `Diagnosis`.

    The steps (`_Workflow`): base fit; then, until nothing passes or `max_effects` are named,
    locate, screen, refit, held-out check and name; backward check; where the misfit is still
    above the noise, the exchange check (`fitting.diagnosis.exchange`), after which the rounds
    resume; report.
    """
    began = time.perf_counter()
    experiments = as_experiments(experiments)
    nuisances = NUISANCES if nuisances is None else tuple(resolve_name(name, where="nuisances") for name in nuisances)
    free = tuple(parse_parameter_list(free, where="free")) if free else ()
    for name in nuisances:
        if get_spec(name).scope == "global":
            raise DiagnosisError(f"nuisances: {public_label(name)} is a global parameter; give it in `free`.")
    if candidates is not None:
        for name in candidates:
            if name not in fx.EFFECT_NAMES:
                raise DiagnosisError(f"candidates: unknown effect {name!r}; effects: {', '.join(fx.EFFECT_NAMES)}.")
    search = _Search(experiments, free=free, nuisances=nuisances, steps_per_contact=steps_per_contact,
                     candidates=candidates, min_share=min_share, report=progress)
    run = _Workflow(search, model, min_share=min_share, max_refits=max_refits, progress=progress)
    search.log(f"{len(experiments)} files, {search.n} residuals; compiling the model ...")
    run.base_fit()
    while True:
        while len(run.named_effects) < max_effects and run.round():
            pass
        run.backward_check()
        if not run.exchange_check():
            break
    settings = {"free": [public_label(n) for n in free], "nuisances": [public_label(n) for n in nuisances],
                "max_effects": max_effects,
                "steps_per_contact": steps_per_contact}
    return run.report(settings, began)
