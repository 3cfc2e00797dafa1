"""Experiment design: predicted uncertainties before the experiment, and better plans.

A plan is a set of experiments (`fitting.data.Experiment`): impact velocities, recorded
channels, time axes and noise levels. Trace files define one directly (their headers,
channels, time grids and `noise_std_n`); `plan_experiments` builds one from a few numbers.

**Fisher information.** With the fit's own whitened residuals $r = (\\text{model} - y)/
\\sigma$ and their Jacobian $J$ with respect to the physical parameters (SI), from
`fitting.model.residuals_and_jacobian` (the forward model of `fitting.fit`, not a copy),
the Fisher information is $I = J^TJ$ and the Cramér–Rao bound on the covariance of an
unbiased estimate is $I^{-1}$. The Jacobian does not depend on the data, only on the plan
and on the parameter values, which are given (`values`: the values expected, e.g. from a
previous fit).

**Nuisances.** By default the nuisances (striker velocity, trigger offset, channel gains)
are *fixed*: taken as known from the trace headers, exactly as `hertzchain fit` does with its
default parameters (eta, mu, C). Name them in `nuisances` to make them free: they then get
one value per file (gains one per channel) and are *marginalised*: the standard errors of
the parameters of interest are the corresponding block of the full inverse,
$[(J^TJ)^{-1}]_{\\theta\\theta}$, i.e. the inverse of the Schur complement of the
nuisance block.

**Singular plans.** When $J$ has a direction the plan cannot see (a singular value of the
column-normalised $J$ below 1e-6 of the largest, as in `fitting.uncertainty`), `DesignError`
names the parameters taking part, e.g. a uniform stiffness scale C against a free striker
velocity and free gains (an exact symmetry of the dissipationless chain).

**Optimal plans.** `optimize_plan` chooses, from candidate impact velocities and recorded
channels (contacts and the wall), the `size` (velocity, channel) recordings that
maximise the D-optimality criterion $\\log\\det(D\\,M\\,D)$, $M$ the (marginal) Fisher
information of the parameters of interest and $D$ the diagonal of their values (so the
criterion is the log volume of the relative-uncertainty ellipsoid, unit-free), or minimise
the A-criterion $\\sum_i (\\sigma_i/\\theta_i)^2$. The search is greedy forward selection
followed by exchange passes (swap one chosen recording for one not chosen while that
improves the criterion). Recordings at the same velocity are one shot (they share that
shot's striker velocity and trigger offset when those are free).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from hertzchain.atomic import json_ready
from hertzchain.chain import ChainSetup
from hertzchain.covariance import gauss_newton_covariance, information_rows
from hertzchain.progress import Progress
from hertzchain.tracefile import TraceFile, setup_header

from .data import Experiment, as_experiments, make_experiment
from .fit import OPTIMUM_TOLERANCE, fit_datasets, make_problem
from .model import ForwardModel, Problem, residuals_and_jacobian
from .parameters import get_spec, parse_parameter_list
from .synthetic import simulate_clean

# Verlet steps per contact time of the noise-free data of a planned experiment: the design
# uses the data only for the fit's input checks and its choice of simulation sampling.
_PLAN_STEPS = 100

NUISANCES = ("striker_velocity", "time_offset", "gain")
CRITERIA = ("D", "A")


class DesignError(ValueError):
    """A plan that cannot determine the chosen parameters; the message names them."""


# --- plans ---------------------------------------------------------------------------------------
def plan_experiments(
    setup: ChainSetup,
    velocities_m_s: Sequence[float],
    *,
    channels: Sequence[str] = ("wall",),
    noise_std_n: float = 0.5,
    sample_interval_s: float = 1e-6,
    t_end_s: float = 2.5e-3,
    coupling: str = "dc",
) -> list[Experiment]:
    """A plan from a few numbers: one shot per impact velocity, recording `channels`.

    **Arguments:**

    - `setup`: the chain, with the parameter values expected (eta, mu, mu_star, ...).
    - `velocities_m_s`: impact velocities, m/s (one experiment each).
    - `channels`: recorded channels of every shot (`contact_K`, `wall`, `sensor_K`; sensors
      need `setup.sensor_beads`).
    - `noise_std_n`: white-noise standard deviation of every channel, N.
    - `sample_interval_s`, `t_end_s`: the recorded time axis.
    - `coupling`: `"dc"`, or `"ac"` for piezo sensors that read changes of force only (a
      static preload of `setup` is then not in the channels).

    The experiments carry noise-free simulated data (the design does not use data values;
    the data checks of `fitting.data` still apply: a channel the pulse does not reach within
    `t_end_s`, or sampling too coarse for the pulse, is refused with a message).
    """
    velocities = [float(v) for v in velocities_m_s]
    if not velocities:
        raise ValueError("velocities: give at least one impact velocity (m/s).")
    if any(not (v > 0 and math.isfinite(v)) for v in velocities):
        raise ValueError(f"velocities must be positive (m/s), got {velocities}.")
    if not noise_std_n > 0:
        raise ValueError(f"noise_std_n must be positive (N), got {noise_std_n}.")
    if coupling not in ("dc", "ac"):
        raise ValueError(f"coupling must be 'dc' or 'ac', got {coupling!r}.")
    channels = tuple(channels)
    contacts = _contacts_of(setup, channels)
    setups = [
        eqx.tree_at(lambda s: s.striker_velocity_m_s, setup, jnp.asarray(v, dtype=jnp.float64))
        for v in velocities
    ]
    n_samples = round(t_end_s / sample_interval_s)
    clean = simulate_clean(setups, contacts=contacts, t_end_s=n_samples * sample_interval_s,
                           sample_interval_s=sample_interval_s, steps_per_contact=_PLAN_STEPS)
    time = sample_interval_s * np.arange(1, n_samples + 1)
    experiments = []
    for k, (s, v) in enumerate(zip(setups, velocities)):
        header = setup_header(s)
        header["noise_std_n"] = float(noise_std_n)
        rest = float(s.precompression_n) if coupling == "ac" else 0.0
        data = {name: clean[k][name] - rest for name in channels}
        if coupling == "ac":
            header["ac_channels"] = ",".join(channels)
        trace = TraceFile(header=header, time_s=time, channels=data, path=None)
        experiments.append(make_experiment(trace, label=f"v{k + 1}_{v:g}", channels=channels,
                                           noise_std_n=noise_std_n))
    return experiments


def _contacts_of(setup: ChainSetup, channels) -> tuple[int, ...]:
    contacts = []
    for name in channels:
        kind, _, number = name.partition("_")
        if name == "wall":
            if setup.end != "wall":
                raise ValueError("channels: this chain has a free end, no wall channel.")
        elif kind == "contact" and number.isdigit() and 0 <= int(number) < setup.n_beads:
            contacts.append(int(number))
        elif kind == "sensor" and number.isdigit() and int(number) in setup.sensor_beads:
            pass
        else:
            raise ValueError(
                f"channels: {name!r} is not a channel of this chain; channels are contact_K "
                f"(K = 0..{setup.n_beads - 1}), wall, and sensor_K for sensor beads "
                f"{list(setup.sensor_beads) or '(none)'}."
            )
    return tuple(sorted(set(contacts)))


# --- the Fisher information -----------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class DesignResult:
    """Predicted uncertainties of a plan (Cramér–Rao).

    **Fields:**

    - `params`: the parameters of interest; `values`, `stderr`, `relative_stderr`: name ->
      SI value, predicted standard error, stderr/|value|; `units`.
    - `correlation`: (p, p) predicted correlation matrix of the parameters of interest.
    - `covariance`: (p, p) predicted covariance (SI).
    - `nuisances`: the free nuisance parameters (marginalised); () = fixed (known).
    - `labels`: every free number of the plan (interest then nuisances, as `fit` names them);
      `fisher`: the full Fisher information $J^TJ$ in `labels` order (SI).
    - `criterion`: {"D": log det of the relative marginal information, "A": sum of squared
      relative standard errors}.
    - `plan`: one dict per experiment (label, striker velocity, channels, noise, sampling,
      duration).
    """

    params: tuple
    values: dict
    stderr: dict
    relative_stderr: dict
    units: dict
    correlation: np.ndarray
    covariance: np.ndarray
    nuisances: tuple
    labels: tuple
    fisher: np.ndarray
    criterion: dict
    plan: list

    def to_json(self) -> dict:
        return {
            "params": {
                p: {"value": json_ready(self.values[p]), "stderr": json_ready(self.stderr[p]),
                    "relative_stderr": json_ready(self.relative_stderr[p]), "unit": self.units[p]}
                for p in self.params
            },
            "correlation": {
                "names": list(self.params),
                "matrix": [[json_ready(c) for c in row] for row in np.asarray(self.correlation)],
            },
            "nuisances": {
                "free": list(self.nuisances),
                "treatment": "free and marginalised" if self.nuisances
                else "fixed (striker velocity, trigger offset and gains known)",
            },
            "criterion": {k: json_ready(v) for k, v in self.criterion.items()},
            "plan": self.plan,
        }


def _plan_summary(experiments: Sequence[Experiment]) -> list[dict]:
    rows = []
    for e in experiments:
        rows.append({
            "label": e.label,
            "striker_velocity_m_s": e.trace.striker_velocity_m_s,
            "channels": list(e.channels),
            "noise_std_n": {c: float(s) for c, s in e.noise_std_n.items()},
            "sample_interval_s": float(e.trace.sample_interval_s),
            "t_end_s": float(e.time_s[-1]),
            "path": e.trace.path,
        })
    return rows


def _check_names(params, nuisances) -> tuple[tuple[str, ...], tuple[str, ...]]:
    params = parse_parameter_list(params)
    for name in params:
        if name in NUISANCES:
            raise ValueError(
                f"params: {name} is a nuisance; list it in nuisances to make it free "
                f"(nuisances: {', '.join(NUISANCES)})."
            )
        if get_spec(name).scope != "global":
            raise ValueError(f"params: {name} is not a global parameter.")
    nuisances = tuple(dict.fromkeys(nuisances))
    for name in nuisances:
        if name not in NUISANCES:
            raise ValueError(f"nuisances: unknown nuisance {name!r}; nuisances are {', '.join(NUISANCES)}.")
    return params, nuisances


def _setup_with_values(setup: ChainSetup, values: Mapping[str, float], skip=()) -> ChainSetup:
    for name, value in values.items():
        if name in skip:
            continue
        spec = get_spec(name)
        if spec.kind != "setup" or spec.scope != "global":
            raise ValueError(f"values: {name} is not a global physical parameter.")
        setup = spec.apply(setup, float(value))
    return setup


class _Plan:
    """The Problem of a plan and its parameter vector at the given values."""

    def __init__(self, experiments, params, nuisances, values, forward):
        values = dict(values or {})
        for name in values:
            get_spec(name)
        if "C" in params and "mu_star" in values:
            # C is set through the stiffness scale: apply mu* to read C, do not fix it
            fixed = {k: v for k, v in values.items() if k not in params and k != "mu_star"}
        else:
            fixed = {k: v for k, v in values.items() if k not in params}
        if "mu_star" in params and "C" in values:
            raise ValueError("values: give mu_star, not C, when mu_star is the designed parameter.")
        self.problem: Problem = make_problem(experiments, params + nuisances, fixed=fixed,
                                             forward=forward)
        truth = [_setup_with_values(s, values) for s in self.problem.base_setups]
        x = []
        for inst in self.problem.instances:
            spec = inst.spec
            if spec.kind == "setup":
                setup = truth[inst.experiment if inst.experiment is not None else 0]
                x.append(float(values[inst.name]) if inst.name in values and inst.name != "C"
                         else float(spec.read(setup)))
            else:
                x.append(float(spec.default))
        self.x = np.asarray(x)
        for i, inst in enumerate(self.problem.instances):
            if inst.name in params and not self.x[i] != 0:
                raise ValueError(
                    f"values: {inst.name} is 0 in the plan's setup; give the value you expect "
                    f"(e.g. --{inst.name.replace('_', '-')} ...): the design is made at that value."
                )
        self.params = params
        self.nuisances = nuisances
        self.interest = [i for i, inst in enumerate(self.problem.instances) if inst.name in params]

    def jacobian(self) -> np.ndarray:
        _, jac = residuals_and_jacobian(self.problem, self.x)
        if not np.all(np.isfinite(jac)):
            raise DesignError("the Jacobian of the residuals is not finite at these parameter values.")
        return jac


def _degeneracy_message(fisher, labels, gauss_newton) -> str | None:
    """Name the parameters of directions the plan cannot see (None if there are none);
    `gauss_newton` is `fisher`'s `hertzchain.covariance.GaussNewtonCovariance`."""
    diag = np.diag(fisher)
    blind = [labels[j] for j in range(len(labels)) if not diag[j] > 0]
    singular = gauss_newton.singular_values
    top = singular[0] if singular[0] > 0 else 1.0
    parts = []
    if blind:
        parts.append(f"the residuals do not depend on {', '.join(blind)} at all")
    for k in np.nonzero(~gauss_newton.kept)[0]:
        direction = gauss_newton.directions[k]
        names = [labels[j] for j in range(len(labels)) if abs(direction[j]) > 0.1 and labels[j] not in blind]
        if names:
            parts.append(
                f"{', '.join(names)} can change together without changing any residual "
                f"(relative singular value {singular[k] / top:.1e})"
            )
    if not parts:
        return None
    return (
        "the Fisher matrix of this plan is singular: it cannot separate the parameters: "
        + "; ".join(parts) + ". Fix a nuisance (take it from the header), add experiments "
        "(other impact velocities, other channels), or design fewer parameters."
    )


def _result_from_fisher(fisher, labels, x, interest, nuisances, units, plan_rows) -> DesignResult:
    labels = tuple(labels)
    gauss_newton = gauss_newton_covariance(information_rows(fisher))
    message = _degeneracy_message(fisher, labels, gauss_newton)
    if message:
        raise DesignError(message)
    covariance = gauss_newton.covariance
    idx = list(interest)
    cov = covariance[np.ix_(idx, idx)]
    stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    correlation = cov / np.outer(stderr, stderr)
    names = [labels[i] for i in idx]
    relative = {n: float(stderr[k] / abs(x[i])) for k, (n, i) in enumerate(zip(names, idx))}
    scale = np.abs(np.asarray(x)[idx])
    sign, logdet = np.linalg.slogdet(np.linalg.inv(cov) * np.outer(scale, scale))
    return DesignResult(
        params=tuple(names),
        values={n: float(x[i]) for n, i in zip(names, idx)},
        stderr={n: float(stderr[k]) for k, n in enumerate(names)},
        relative_stderr=relative,
        units={n: units[i] for n, i in zip(names, idx)},
        correlation=correlation,
        covariance=cov,
        nuisances=tuple(nuisances),
        labels=labels,
        fisher=fisher,
        criterion={"D": float(logdet) if sign > 0 else -math.inf,
                   "A": float(sum(r**2 for r in relative.values()))},
        plan=plan_rows,
    )


def _result_from_jacobian(plan: _Plan, jac, experiments) -> DesignResult:
    units = [inst.spec.unit for inst in plan.problem.instances]
    return _result_from_fisher(jac.T @ jac, plan.problem.labels, plan.x, plan.interest,
                               plan.nuisances, units, _plan_summary(experiments))


def design(plan, params=("eta", "mu", "C"), *, values=None, nuisances=(),
           forward: ForwardModel | None = None) -> DesignResult:
    """Predicted standard errors and correlations of `params` for a plan (Cramér–Rao).

    **Arguments:**

    - `plan`: `Experiment`s (e.g. from `plan_experiments`), `TraceFile`s or trace-file paths:
      their headers (chain, striker velocity), channels, time axes and noise levels define
      the experiments (a file without `noise_std_n` gets the noise estimated from its data).
    - `params`: global parameters of interest, names and units as `fitting.fit` (eta in s,
      mu, C in m/s N^-1/6, mu_star, wall_youngs, ...).
    - `values`: name -> SI value of the physical parameters expected (eta, mu, mu_star or C,
      ...); parameters not given keep the trace headers' values (eta = mu = 0 there, which
      would make the design meaningless for them: give them).
    - `nuisances`: free nuisances to marginalise, from `NUISANCES`; default none (fixed).
    - `forward`: the fit's `ForwardModel` (time step, model switches).

    **Returns:** `DesignResult`. **Raises:** `DesignError` for a plan whose Fisher matrix is
    singular (naming the parameters it cannot separate).
    """
    params, nuisances = _check_names(params, nuisances)
    experiments = as_experiments(plan)
    plan_ = _Plan(experiments, params, nuisances, values, forward)
    return _result_from_jacobian(plan_, plan_.jacobian(), experiments)


# --- optimal plans -------------------------------------------------------------------------------
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
                p: self.recommended.stderr[p] / self.baseline.stderr[p]
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
    params=("eta", "mu", "C"),
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
        reference = design(baseline, params, values=values, nuisances=nuisances, forward=forward)
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


# --- checking a design against actual fits -------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class FitScatter:
    """Scatter of actual least-squares fits over noise seeds, against the design's prediction.

    **Fields:** `params`; `truth` (name -> value); `estimates` (n_seeds, p) fitted values of
    the converged fits; `empirical_std`, `predicted_stderr`, `ratio` (empirical/predicted),
    `bias` (mean - truth) per parameter; `n_seeds`, `n_converged`; `design` (`DesignResult`).
    """

    params: tuple
    truth: dict
    estimates: np.ndarray
    empirical_std: dict
    predicted_stderr: dict
    ratio: dict
    bias: dict
    n_seeds: int
    n_converged: int
    design: DesignResult

    def to_json(self) -> dict:
        return {
            "method": "Levenberg-Marquardt fits (the residuals, parameter transforms and solver of "
            "fitting.fit) of the plan's noise-free model plus white Gaussian noise of the stated "
            "sigma, one fit per seed, started at the truth",
            "n_seeds": self.n_seeds,
            "n_converged": self.n_converged,
            "params": {
                p: {"truth": self.truth[p], "predicted_stderr": self.predicted_stderr[p],
                    "empirical_std": self.empirical_std[p], "ratio": self.ratio[p],
                    "bias": self.bias[p]}
                for p in self.params
            },
        }


def fit_scatter(plan, params=("eta", "mu", "C"), *, values=None, nuisances=(), n_seeds: int = 50,
                seed: int = 0, chunk_size: int = 25, max_steps: int = 100, tolerance: float = OPTIMUM_TOLERANCE,
                forward: ForwardModel | None = None, progress: bool = True) -> FitScatter:
    """Fit `n_seeds` noisy copies of a plan's data and compare the scatter with `design`.

    The data of every seed is the fit model at the given values plus white Gaussian noise of
    each channel's sigma (N); each copy is fitted by `fitting.fit.fit_datasets`, i.e. with
    `fitting.fit`'s residuals, bounded parameter transforms, Levenberg-Marquardt solver,
    `tolerance` (on chi^2, dimensionless) and convergence test, started at the truth; the
    seeds run as vmapped batches of `chunk_size` (one compilation for all). Free nuisances
    are fitted too.
    """
    params, nuisances = _check_names(params, nuisances)
    experiments = as_experiments(plan)
    plan_ = _Plan(experiments, params, nuisances, values, forward)
    predicted = _result_from_jacobian(plan_, plan_.jacobian(), experiments)
    problem = plan_.problem
    x = plan_.x
    truth = dict(zip(problem.labels, map(float, x)))
    clean = np.asarray(problem.model_vector(x))
    sigma = problem.sigma_vector()
    sigma = np.where(np.isfinite(sigma), sigma, 0.0)  # samples left out of the fit stay clean
    rng = np.random.default_rng(seed)
    noises = rng.standard_normal((n_seeds, clean.size))
    chunk = max(1, min(chunk_size, n_seeds))
    meter = Progress(n_seeds, "fits over noise seeds") if progress else None
    estimates, converged = [], []
    for start in range(0, n_seeds, chunk):
        part = noises[start:start + chunk]
        count = part.shape[0]
        if count < chunk:  # the last batch padded to the same size: no second compilation
            part = np.concatenate([part, np.repeat(part[-1:], chunk - count, axis=0)])
        fits = fit_datasets(problem, clean + sigma * part, start=truth, max_steps=max_steps,
                            tolerance=tolerance)
        estimates.append(fits["values"][:count])
        converged.append(fits["converged"][:count])
        if meter:
            meter.advance(count)
    estimates = np.concatenate(estimates)
    converged = np.concatenate(converged)
    fitted = estimates[converged][:, plan_.interest]
    if fitted.shape[0] < 2:
        raise DesignError(f"only {fitted.shape[0]} of {n_seeds} fits converged; the scatter is undefined.")
    names = predicted.params
    std = {n: float(np.std(fitted[:, k], ddof=1)) for k, n in enumerate(names)}
    return FitScatter(
        params=names,
        truth=dict(predicted.values),
        estimates=fitted,
        empirical_std=std,
        predicted_stderr=dict(predicted.stderr),
        ratio={n: std[n] / predicted.stderr[n] for n in names},
        bias={n: float(np.mean(fitted[:, k]) - predicted.values[n]) for k, n in enumerate(names)},
        n_seeds=n_seeds,
        n_converged=int(converged.sum()),
        design=predicted,
    )


# --- plots ---------------------------------------------------------------------------------------
def plot_design(result: DesignResult, *, baseline: DesignResult | None = None, title: str | None = None):
    """Predicted relative standard errors (bars, log scale) and the correlation matrix."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (bars, matrix) = plt.subplots(1, 2, figsize=(10, 4))
    x = np.arange(len(result.params))
    width = 0.38 if baseline is not None else 0.6
    if baseline is not None:
        bars.bar(x - width / 2, [100 * baseline.relative_stderr[p] for p in result.params], width,
                 label="before (given plan)", color="tab:gray")
    bars.bar(x + (width / 2 if baseline is not None else 0),
             [100 * result.relative_stderr[p] for p in result.params], width,
             label="recommended plan" if baseline is not None else "plan", color="tab:blue")
    bars.set_xticks(x, result.params)
    bars.set_yscale("log")
    bars.set_ylabel("predicted standard error (% of value)")
    bars.legend(fontsize=8)
    bars.set_title(title or "Cramér–Rao standard errors")
    image = matrix.imshow(result.correlation, vmin=-1, vmax=1, cmap="RdBu_r")
    matrix.set_xticks(x, result.params)
    matrix.set_yticks(x, result.params)
    for i in range(len(x)):
        for j in range(len(x)):
            matrix.text(j, i, f"{result.correlation[i, j]:.2f}", ha="center", va="center", fontsize=8)
    matrix.set_title("predicted correlation")
    figure.colorbar(image, ax=matrix)
    figure.tight_layout()
    return figure
