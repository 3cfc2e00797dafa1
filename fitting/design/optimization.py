"""Optimal plans: the recordings, from candidate velocities and channels, that maximise
the D criterion or minimise the A criterion (greedy selection, then exchange passes)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from hertzchain.chain import ChainSetup
from hertzchain.progress import Progress

from ..data import Experiment
from ..model import ForwardModel
from ..parameters import public_keys, public_label
from .plan import (
    CRITERIA,
    NUISANCES,
    DesignResult,
    _check_names,
    _Plan,
    _plan_summary,
    _result_from_fisher,
    design,
    plan_experiments,
)


@dataclasses.dataclass(frozen=True)
class PlanOptimization:
    """A recommended plan and how it compares with a reference plan.

    **Fields:** `criterion` ("D" or "A"); `size` (recordings chosen); `chosen`: list of
    (velocity m/s, channel) recordings; `recommended`: its `DesignResult`; `baseline`: the
    reference plan's `DesignResult` (or None); `candidates`: (velocities, channels) searched;
    `history`: criterion after each greedy addition and exchange pass.
    """

    criterion: str
    size: int
    chosen: list
    recommended: DesignResult
    baseline: DesignResult | None
    candidates: dict
    history: list
    evaluate: Callable = dataclasses.field(repr=False, compare=False, default=None)
    candidate_experiments: list = dataclasses.field(repr=False, compare=False, default_factory=list)

    def experiments(self, units=None) -> list[Experiment]:
        """The `Experiment`s of the recommended plan (or of any candidate `units`), e.g. to
        check it with `fit_scatter` or to simulate it."""
        units = self.chosen if units is None else [(float(v), c) for v, c in units]
        velocities = self.candidates["velocities_m_s"]
        out = []
        for e, experiment in enumerate(self.candidate_experiments):
            channels = tuple(c for v, c in units if v == velocities[e])
            if channels:
                out.append(dataclasses.replace(
                    experiment, channels=channels,
                    noise_std_n={c: experiment.noise_std_n[c] for c in channels},
                ))
        return out

    def to_json(self) -> dict:
        out = {
            "criterion": self.criterion,
            "criterion_meaning": "D: maximise log det of the relative (marginal) Fisher information "
            "of the parameters of interest; A: minimise the sum of squared relative standard errors",
            "search": "greedy forward selection, then exchange passes",
            "size": self.size,
            "chosen": [{"striker_velocity_m_s": v, "channel": c} for v, c in self.chosen],
            "candidates": self.candidates,
            "recommended": self.recommended.to_json(),
            "history": self.history,
        }
        if self.baseline is not None:
            out["baseline"] = self.baseline.to_json()
            out["stderr_ratio_recommended_over_baseline"] = {
                public_label(p): self.recommended.stderr[p] / self.baseline.stderr[p]
                for p in self.recommended.params
            }
        return out


def _score(blocks, chosen, interest, nuisance_of, values_abs, criterion) -> float:
    """Criterion of a set of recordings from per-recording Fisher blocks (larger is better)."""
    if not chosen:
        return -math.inf
    fisher = sum(blocks[u] for u in chosen)
    nuis = sorted({j for u in chosen for j in nuisance_of[u]})
    f_ii = fisher[np.ix_(interest, interest)]
    if nuis:
        f_in = fisher[np.ix_(interest, nuis)]
        f_nn = fisher[np.ix_(nuis, nuis)]
        try:
            f_ii = f_ii - f_in @ np.linalg.solve(f_nn, f_in.T)
        except np.linalg.LinAlgError:
            return -math.inf
    m = f_ii * np.outer(values_abs, values_abs)
    scale = np.trace(m)
    if not np.isfinite(scale) or scale <= 0:
        return -math.inf
    eig = np.linalg.eigvalsh(m)
    if criterion == "D":
        # a tiny ridge keeps rank-deficient early greedy steps comparable
        return float(np.sum(np.log(np.maximum(eig, 0) + 1e-12 * scale)))
    if np.min(eig) <= 1e-12 * scale:
        return -1e300 * (1 + np.sum(eig <= 1e-12 * scale))
    return -float(np.trace(np.linalg.inv(m)))


def optimize_plan(
    setup: ChainSetup,
    params=("eta_s", "mu", "C"),
    *,
    candidate_velocities_m_s: Sequence[float],
    candidate_channels: Sequence[str],
    size: int,
    values=None,
    nuisances=(),
    noise_std_n: float = 0.5,
    sample_interval_s: float = 1e-6,
    t_end_s: float = 2.5e-3,
    criterion: str = "D",
    baseline_units: Sequence[tuple[float, str]] | None = None,
    baseline=None,
    forward: ForwardModel | None = None,
    max_passes: int = 10,
    progress: bool = True,
) -> PlanOptimization:
    """The plan of `size` (velocity, channel) recordings that best determines `params`.

    **Arguments:**

    - `setup`: the chain with the expected parameter values (and `values` on top).
    - `candidate_velocities_m_s`, `candidate_channels`: the candidates (channels: `wall`,
      `contact_K`, `sensor_K`); every velocity x channel pair is a candidate recording.
    - `size`: how many recordings to choose.
    - `noise_std_n`, `sample_interval_s`, `t_end_s`: of every recording.
    - `criterion`: "D" (default) or "A" (see the module docstring).
    - `baseline_units`: a reference plan as (velocity, channel) recordings (added to the
      candidates), or `baseline`: a reference plan as for `design` (files, experiments).
    - other arguments as `design`.

    **Returns:** `PlanOptimization` (`recommended` and `baseline` predictions).
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}.")
    params, nuisances = _check_names(params, nuisances)
    baseline_units = [(float(v), str(c)) for v, c in (baseline_units or [])]
    velocities = sorted({float(v) for v in candidate_velocities_m_s} | {v for v, _ in baseline_units})
    channels = tuple(dict.fromkeys(list(candidate_channels) + [c for _, c in baseline_units]))
    n_units = len(velocities) * len(channels)
    if not 1 <= size <= n_units:
        raise ValueError(f"size must be between 1 and the {n_units} candidate recordings, got {size}.")
    experiments = plan_experiments(setup, velocities, channels=channels, noise_std_n=noise_std_n,
                                   sample_interval_s=sample_interval_s, t_end_s=t_end_s)
    plan = _Plan(experiments, params, nuisances, values, forward)
    jac = plan.jacobian()
    instances = plan.problem.instances
    interest = plan.interest
    slices = plan.problem.residual_slices()
    units, blocks, nuisance_of = [], [], []
    for e, experiment in enumerate(experiments):
        for channel in experiment.channels:
            rows = jac[slices[e][channel]]
            units.append((velocities[e], channel))
            blocks.append(rows.T @ rows)
            nuisance_of.append([
                j for j, inst in enumerate(instances)
                if inst.name in NUISANCES and inst.experiment == e
                and (inst.channel is None or inst.channel == channel)
            ])
    values_abs = np.abs(plan.x[interest])
    score = lambda chosen: _score(blocks, chosen, interest, nuisance_of, values_abs, criterion)  # noqa: E731
    meter = Progress(size + max_passes, "design optimisation") if progress else None
    chosen: list[int] = []
    history = []
    for _ in range(size):
        best = max((u for u in range(len(units)) if u not in chosen), key=lambda u: score(chosen + [u]))
        chosen.append(best)
        history.append({"step": f"add {units[best][1]} at {units[best][0]:g} m/s", "score": score(chosen)})
        if meter:
            meter.advance()
    for _ in range(max_passes):
        improved = False
        current = score(chosen)
        for i in range(len(chosen)):
            for u in range(len(units)):
                if u in chosen:
                    continue
                trial = chosen[:i] + [u] + chosen[i + 1:]
                value = score(trial)
                if value > current + 1e-9 * max(1.0, abs(current)):
                    history.append({"step": f"swap {units[chosen[i]][1]} at {units[chosen[i]][0]:g} m/s "
                                            f"for {units[u][1]} at {units[u][0]:g} m/s", "score": value})
                    chosen, current, improved = trial, value, True
        if meter:
            meter.advance()
        if not improved:
            break
    if meter:
        meter.advance(meter.total)

    def subset_result(subset: list[int]) -> DesignResult:
        columns = list(interest) + sorted({j for u in subset for j in nuisance_of[u]})
        fisher = sum(blocks[u] for u in subset)[np.ix_(columns, columns)]
        labels = [plan.problem.labels[j] for j in columns]
        units_of = [instances[j].spec.unit for j in columns]
        rows = _subset_summary(experiments, velocities, [units[u] for u in subset])
        return _result_from_fisher(fisher, labels, plan.x[columns], range(len(interest)),
                                   nuisances, units_of, rows)

    def evaluate(recordings) -> DesignResult:
        """Predicted uncertainties of any set of candidate (velocity, channel) recordings."""
        subset = []
        for v, c in recordings:
            if (float(v), c) not in units:
                raise ValueError(f"({v:g} m/s, {c}) is not a candidate recording.")
            subset.append(units.index((float(v), c)))
        return subset_result(sorted(set(subset)))

    recommended = subset_result(sorted(chosen))
    reference = None
    if baseline_units:
        reference = subset_result([units.index(u) for u in baseline_units])
    elif baseline is not None:
        reference = design(baseline, tuple(map(public_label, params)), values=public_keys(plan.values),
                           nuisances=tuple(map(public_label, nuisances)), forward=forward)
    return PlanOptimization(
        criterion=criterion,
        size=size,
        chosen=sorted((float(units[u][0]), units[u][1]) for u in chosen),
        recommended=recommended,
        baseline=reference,
        candidates={"velocities_m_s": velocities, "channels": list(channels)},
        history=history,
        evaluate=evaluate,
        candidate_experiments=experiments,
    )


def _subset_summary(experiments, velocities, chosen_units) -> list[dict]:
    rows = []
    for row, e in zip(_plan_summary(experiments), range(len(experiments))):
        channels = [c for v, c in chosen_units if v == velocities[e]]
        if channels:
            row = dict(row, channels=channels,
                       noise_std_n={c: row["noise_std_n"][c] for c in channels})
            rows.append(row)
    return rows
