"""Plans and their predicted uncertainties: a plan's Fisher information, its marginal
covariance (Cramér–Rao), and the singular directions it cannot see."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from hertzchain.chain import ChainSetup
from hertzchain.covariance import gauss_newton_covariance, information_rows
from hertzchain.io.atomic import json_ready
from hertzchain.io.tracefile import TraceFile, setup_header

from ..data import Experiment, as_experiments, make_experiment
from ..fit import make_problem
from ..model import ForwardModel, Problem, residuals_and_jacobian
from ..parameters import (
    LabelledValues,
    get_spec,
    parse_parameter_list,
    public_keys,
    public_label,
    resolve_name,
)
from ..synthetic import simulate_clean

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

    - `params`: the parameters of interest (registry keys, as `FitResult.labels`); `values`,
      `stderr`, `relative_stderr`: name -> SI value, predicted standard error, stderr/|value|;
      `units` (read by either spelling, `fitting.parameters.LabelledValues`). `to_json` names
      them as a user writes them (`eta_s`, `wall_youngs_pa`: `public_label`).
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
                public_label(p): {"value": json_ready(self.values[p]), "stderr": json_ready(self.stderr[p]),
                                  "relative_stderr": json_ready(self.relative_stderr[p]), "unit": self.units[p]}
                for p in self.params
            },
            "correlation": {
                "names": [public_label(p) for p in self.params],
                "matrix": [[json_ready(c) for c in row] for row in np.asarray(self.correlation)],
            },
            "nuisances": {
                "free": [public_label(n) for n in self.nuisances],
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
    """The registry keys of `params` and `nuisances` (either spelling: a previous name warns),
    checked."""
    params = parse_parameter_list(params, where="params")
    shown = ", ".join(map(public_label, NUISANCES))
    for name in params:
        if name in NUISANCES:
            raise ValueError(
                f"params: {public_label(name)} is a nuisance; list it in nuisances to make it free "
                f"(nuisances: {shown})."
            )
        if get_spec(name).scope != "global":
            raise ValueError(f"params: {public_label(name)} is not a global parameter.")
    keys = []
    for name in nuisances:
        try:
            key = resolve_name(name, where="nuisances")
        except ValueError:
            key = None
        if key not in NUISANCES:
            raise ValueError(f"nuisances: unknown nuisance {name!r}; nuisances are {shown}.")
        keys.append(key)
    return params, tuple(dict.fromkeys(keys))


def _setup_with_values(setup: ChainSetup, values: Mapping[str, float], skip=()) -> ChainSetup:
    for name, value in values.items():
        if name in skip:
            continue
        spec = get_spec(name)
        if spec.kind != "setup" or spec.scope != "global":
            raise ValueError(f"values: {public_label(name)} is not a global physical parameter.")
        setup = spec.apply(setup, float(value))
    return setup


class _Plan:
    """The Problem of a plan and its parameter vector at the given values (`params`,
    `nuisances`: registry keys; `values`: as the user wrote them, a previous name warns)."""

    def __init__(self, experiments, params, nuisances, values, forward):
        values = {resolve_name(name, where="values"): value for name, value in (values or {}).items()}
        if "C" in params and "mu_star" in values:
            # C is set through the stiffness scale: apply mu* to read C, do not fix it
            fixed = {k: v for k, v in values.items() if k not in params and k != "mu_star"}
        else:
            fixed = {k: v for k, v in values.items() if k not in params}
        if "mu_star" in params and "C" in values:
            raise ValueError("values: give mu_star, not C, when mu_star is the designed parameter.")
        self.problem: Problem = make_problem(experiments, tuple(map(public_label, params + nuisances)),
                                             fixed=public_keys(fixed), forward=forward)
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
                    f"values: {public_label(inst.name)} is 0 in the plan's setup; give the value you expect "
                    f"(e.g. --{inst.name.replace('_', '-')} ...): the design is made at that value."
                )
        self.params = params
        self.nuisances = nuisances
        self.values = values
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
    labels = [public_label(label) for label in labels]
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
        values=LabelledValues({n: float(x[i]) for n, i in zip(names, idx)}),
        stderr=LabelledValues({n: float(stderr[k]) for k, n in enumerate(names)}),
        relative_stderr=LabelledValues(relative),
        units=LabelledValues({n: units[i] for n, i in zip(names, idx)}),
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


def design(plan, params=("eta_s", "mu", "C"), *, values=None, nuisances=(),
           forward: ForwardModel | None = None) -> DesignResult:
    """Predicted standard errors and correlations of `params` for a plan (Cramér–Rao).

    **Arguments:**

    - `plan`: `Experiment`s (e.g. from `plan_experiments`), `TraceFile`s or trace-file paths:
      their headers (chain, striker velocity), channels, time axes and noise levels define
      the experiments (a file without `noise_std_n` gets the noise estimated from its data).
    - `params`: global parameters of interest, names and units as `fitting.fit` (eta_s in s,
      mu, C in m/s N^-1/6, mu_star, wall_youngs_pa, ...; either spelling).
    - `values`: name -> SI value of the physical parameters expected (eta_s, mu, mu_star or
      C, ...); parameters not given keep the trace headers' values (eta = mu = 0 there, which
      would make the design meaningless for them: give them).
    - `nuisances`: free nuisances to marginalise, from `NUISANCES` (striker_velocity_m_s,
      time_offset_s, gain; either spelling); default none (fixed).
    - `forward`: the fit's `ForwardModel` (time step, model switches).

    **Returns:** `DesignResult`. **Raises:** `DesignError` for a plan whose Fisher matrix is
    singular (naming the parameters it cannot separate).
    """
    params, nuisances = _check_names(params, nuisances)
    experiments = as_experiments(plan)
    plan_ = _Plan(experiments, params, nuisances, values, forward)
    return _result_from_jacobian(plan_, plan_.jacobian(), experiments)
