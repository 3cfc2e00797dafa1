"""What a diagnosis finds: each candidate's result, each step, the whole diagnosis."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from hertzchain.io.atomic import json_ready

from ..model import Problem
from ..parameters import public_keys


@dataclasses.dataclass(frozen=True, kw_only=True)
class CandidateResult:
    """One candidate effect at one step of the search: refitted (`chi2`, `delta_chi2`,
    `bic_gain`, `share_of_excess`, `values`, `stderr`, `x` its parameter vector) or not
    (NaN, with the `reason`); `converged` and `steps`: how its refit ended (None: not refitted)."""

    effect: str
    n_parameters: int
    score_chi2: float
    separable: bool = True
    chi2: float = math.nan
    delta_chi2: float = math.nan
    bic_gain: float = math.nan
    share_of_excess: float = math.nan
    heldout_gain: float | None = None
    values: dict = dataclasses.field(default_factory=dict)
    stderr: dict = dataclasses.field(default_factory=dict)
    passed: bool = False
    reason: str = ""
    converged: bool | None = None
    steps: int = 0
    x: np.ndarray | None = dataclasses.field(default=None, repr=False)

    def to_json(self) -> dict:
        fields = (f.name for f in dataclasses.fields(self) if f.name != "x")
        record = {name: getattr(self, name) for name in fields}
        record["values"], record["stderr"] = public_keys(self.values), public_keys(self.stderr)
        return json_ready(record)


@dataclasses.dataclass
class Step:
    """One named effect: the gap before and after adding it; `status`: how the refit with it
    ended (`converged`, `steps`)."""

    effect: str
    gap_before: float
    gap_after: float
    chi2_before: float
    chi2_after: float
    dof_before: int
    dof_after: int
    values: dict
    stderr: dict
    candidates: list
    location_before: dict
    location_after: dict
    x_before: np.ndarray
    x_after: np.ndarray
    status: dict = dataclasses.field(default_factory=dict)
    replaces: str | None = None  # the effect this one was exchanged for (`fitting.diagnosis.exchange`)

    def to_json(self) -> dict:
        return json_ready({
            "effect": self.effect,
            "replaces": self.replaces,
            **self.status,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "chi2_before": self.chi2_before,
            "chi2_after": self.chi2_after,
            "dof_before": self.dof_before,
            "dof_after": self.dof_after,
            "fitted": public_keys({k: {"value": self.values[k], "stderr": self.stderr.get(k)} for k in self.values}),
            "candidates": [c.to_json() for c in self.candidates],
            "location_before": self.location_before,
            "location_after": self.location_after,
        })


@dataclasses.dataclass
class Diagnosis:
    """What `diagnose` found.

    **Fields:**

    - `missing_effects`: identifiers named, in the order found (empty: nothing missing).
    - `steps`: one `Step` per named effect (gap before/after, fitted strengths, candidates).
    - `base_fit`: chi2, dof, gap (reduced chi2) and values of the base fit.
    - `final`: the same for the final model, with its `location` (residual breakdown).
    - `last_candidates`: the candidates of the round that named nothing.
    - `not_separable`: candidates whose sensitivity lies in the span of the free parameters.
    - `indistinguishable`: candidate pairs with |cos| > 0.95 of their projected sensitivities.
    - `dropped_in_backward_check`: named effects the backward check took out.
    - `exchanged`: the exchanges taken (`fitting.diagnosis.exchange`): the effect put `out`,
      the one put `in`, chi^2 before and after, BIC and held-out gains, the refit's status.
    - `misspecification`: True when the final excess misfit is above the noise band.
    - `conclusion`: one paragraph in words.
    - `unconverged`: the fits the result rests on (named effects' refits, the fits adding
      them, the final fit) that reached no optimum, in words; empty: `converged`.
    - `problem`, `x_base`, `x_final`: the problem and parameter vectors (predictions, plots).
    - `predictions`: x -> the model per experiment, channel -> values on the data's times (N),
      as `Problem.predictions` gives them, on the cheapest equivalent model the diagnosis
      compiled (`_Evaluator.predictions`; the problem's own is the full model with every
      variant of the law on, a compilation of its own).
    """

    missing_effects: list
    steps: list
    base_fit: dict
    final: dict
    last_candidates: list
    not_separable: list
    indistinguishable: list
    dropped_in_backward_check: list
    misspecification: bool
    conclusion: str
    unconverged: list
    settings: dict
    problem: Problem
    predictions: Callable
    x_base: np.ndarray
    x_final: np.ndarray
    elapsed_s: float
    evaluations: int
    evaluation_seconds: float = 0.0
    residual_evaluations: int = 0
    exchanged: list = dataclasses.field(default_factory=list)

    @property
    def converged(self) -> bool:
        """Whether every fit the result rests on reached an optimum."""
        return not self.unconverged

    def to_json(self) -> dict:
        return json_ready({
            "missing_effects": list(self.missing_effects),
            "converged": self.converged,
            "unconverged_fits": list(self.unconverged),
            "steps": [s.to_json() for s in self.steps],
            "base_fit": _public_fit(self.base_fit),
            "final": _public_fit(self.final),
            "last_candidates": [c.to_json() for c in self.last_candidates],
            "not_separable": self.not_separable,
            "indistinguishable": self.indistinguishable,
            "dropped_in_backward_check": self.dropped_in_backward_check,
            "exchanged": self.exchanged,
            "misspecification_alarm": self.misspecification,
            "conclusion": self.conclusion,
            "settings": self.settings,
            "files": [e.trace.path or e.label for e in self.problem.experiments],
            "elapsed_s": self.elapsed_s,
            "model_evaluations": self.evaluations,
            "residual_evaluations": self.residual_evaluations,
            "model_seconds": self.evaluation_seconds,
        })


def _public_fit(summary: dict) -> dict:
    """A fit's summary (`_Report.summary`) with its values and errors keyed by the names a
    user sees (`fitting.parameters.public_label`)."""
    return {key: public_keys(value) if key in ("values", "stderr") else value for key, value in summary.items()}
