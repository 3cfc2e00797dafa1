"""The diagnosis's exchange check (`fitting.diagnosis.exchange`): the decision rule on a search
whose fits return stated chi^2 values (fast), and the case it exists for, a soft wall and viscous
damping hidden in a brass chain simulated by the independent Verlet generator (slow)."""

from __future__ import annotations

import math
import sys
import types
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from fitting.diagnosis import CandidateResult, Step, _Workflow

N_FITTED = 1000
PENALTY = math.log(N_FITTED)


class _TabledSearch:
    """What the exchange check reads of a search: columns 0-1 are nuisances, then each effect's
    strengths; every fit of a set of effects ends at the chi^2 `table` states for it."""

    n_beads = 15
    folds: ClassVar[list] = []
    noise_estimate_variance = 0.0

    class problem:
        n_fitted = N_FITTED

    def __init__(self, strengths: dict, table: dict):
        self.effect_columns, column = {}, 2
        for name, k in strengths.items():
            self.effect_columns[name] = list(range(column, column + k))
            column += k
        self.labels = {c: f"s{c}" for c in range(column)}
        self.width, self.table, self.refits = column, table, []

    def columns(self, effects):
        return [0, 1] + [c for e in effects for c in self.effect_columns[e]]

    def _end(self, effects):
        return types.SimpleNamespace(x=np.ones(self.width), chi2=self.table[frozenset(effects)],
                                     converged=True, steps=4)

    def refit(self, starts, effects, name):
        self.refits.append(name)
        return self._end(effects)

    def fit(self, x, effects, **_):
        return self._end(effects)

    def stderr(self, x, columns, chi2):
        return np.full(len(columns), 0.1)

    def interpret(self, *args):
        return ""

    def log(self, text):
        pass


def _run(strengths, table, named, rivals, chi2):
    """A workflow whose rounds named `named` (each with its round's `rivals`) at `chi2`."""
    search = _TabledSearch(strengths, table)
    run = _Workflow(search, "base", min_share=0.2, max_refits=3, progress=False)
    run.locate = lambda x=None: {"worst": []}
    run.x, run.chi2, run.status, run.accepted = np.ones(search.width), chi2, {"converged": True, "steps": 3}, []
    for effect in named:
        candidates = [CandidateResult(effect=r, n_parameters=strengths[r], score_chi2=0.0,
                                      chi2=table[frozenset(run.accepted + [r])], x=np.ones(search.width))
                      for r in rivals.get(effect, [])]
        run.accepted = run.accepted + [effect]
        run.steps.append(Step(effect=effect, gap_before=0.0, gap_after=0.0, chi2_before=0.0, chi2_after=0.0,
                              dof_before=0, dof_after=0, values={}, stderr={}, candidates=candidates,
                              location_before={}, location_after={}, x_before=run.x, x_after=run.x))
    return run, search


STRENGTHS = {"bead_dispersion": 15, "viscous_damping": 1, "wall_compliance": 1, "track_friction": 1}


def test_a_rival_that_fits_better_in_place_of_a_named_effect_is_exchanged_in():
    """Named: per-bead radii (15 strengths), then viscous damping, still at chi^2 21400 on 982
    dof (the alarm on). In the radii's round the wall (1 strength) came second; viscous + wall
    reach 990: the exchange gains 20410 + 14 ln(1000) by BIC and is taken; the wall is named in
    place of the radii, recorded, and said in the conclusion. The friction, the other rival,
    would reach only 21000 and is not taken."""
    table = {frozenset({"wall_compliance"}): 456029.0, frozenset({"track_friction"}): 470000.0,
             frozenset({"viscous_damping", "wall_compliance"}): 990.0,
             frozenset({"viscous_damping", "track_friction"}): 21000.0,
             frozenset({"viscous_damping", "bead_dispersion"}): 21400.0}
    run, search = _run(STRENGTHS, table, ["bead_dispersion", "viscous_damping"],
                       {"bead_dispersion": ["wall_compliance", "track_friction"]}, 21400.0)
    assert run.exchange_check()
    assert sorted(search.refits) == ["track_friction", "wall_compliance"]
    assert run.named_effects == ["viscous_damping", "wall_compliance"] and run.chi2 == 990.0
    step = run.steps[-1]
    assert step.effect == "wall_compliance" and step.replaces == "bead_dispersion"
    (swap,) = run.exchanged
    assert swap["out"] == "bead_dispersion" and swap["in"] == "wall_compliance"
    assert swap["bic_gain"] == pytest.approx(21400.0 - 990.0 + 14 * PENALTY)
    text = run.conclusion(run.named_effects, {"worst": [], "by_frequency": {}})[1]
    assert "wall_compliance was put in place of bead_dispersion by the exchange check" in text
    # the check repeats until nothing gains: the model at the noise level now tries nothing
    assert not run.exchange_check() and len(search.refits) == 2


def test_an_exchange_that_adds_strengths_must_pay_their_bic_penalty():
    """Named: the wall (1 strength) at chi^2 5000 on 997 dof; its rival, the radii (15), reach
    4900: a gain of 100 against a penalty of 14 ln(1000) = 96.7 is taken; at 4910 (90) it is
    not."""
    for rival_chi2, taken in ((4900.0, True), (4910.0, False)):
        table = {frozenset({"bead_dispersion"}): rival_chi2, frozenset({"wall_compliance"}): 5000.0}
        run, _ = _run(STRENGTHS, table, ["wall_compliance"], {"wall_compliance": ["bead_dispersion"]}, 5000.0)
        assert run.exchange_check() is taken
        assert run.named_effects == (["bead_dispersion"] if taken else ["wall_compliance"])


def test_a_model_at_the_noise_level_is_not_checked():
    """At chi^2 1000 on 997 dof (within the band 3 sqrt(2 x 997) = 134) no exchange is tried,
    even one that would fit better."""
    table = {frozenset({"track_friction"}): 900.0, frozenset({"wall_compliance"}): 1000.0}
    run, search = _run(STRENGTHS, table, ["wall_compliance"], {"wall_compliance": ["track_friction"]}, 1000.0)
    assert not run.exchange_check() and search.refits == []


@pytest.mark.slow
def test_a_soft_wall_with_viscous_damping_in_independent_brass_data_is_named_not_bead_dispersion():
    """The brass chain of the confusion table (`benchmarks/confusion.py --independent --setups
    brass --code-path verlet`), viscous damping and a soft wall hidden, simulated by the
    independent Verlet generator: both named, no alarm (before the exchange check: bead
    dispersion + viscous damping, alarm on)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
    import confusion

    row = confusion.run_case(("viscous_damping", "wall_compliance"), 100, setup="brass", code_path="verlet")
    assert sorted(row["named"]) == ["viscous_damping", "wall_compliance"]
    assert not row["alarm"]
