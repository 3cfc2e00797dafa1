"""Posterior distributions of chain parameters by Hamiltonian Monte Carlo (NUTS).

`sample_posterior(experiments, ("eta_s", "mu", "C"), priors=["bead_youngs_pa=203GPa+-4GPa"])`
samples $p(x \\mid y) \\propto \\exp(-\\chi^2(x)/2)\\, p(x)$ with the same whitened
residuals as the least-squares fit (`fitting.model`, stated noise sigma), so the
posterior is marginal over every nuisance that has a prior (bead modulus and radius,
sensor gains, wall modulus, striker velocities: `fitting.priors`).

How it is sampled:

1. `fitting.fit` finds the maximum a posteriori point (normal priors are residual rows)
   and its Jacobian; the Laplace covariance $(J^T J)^{-1}$ of the transformed coordinates
   $z$ of `fitting.parameters` is the sampler's metric.
2. NUTS (NumPyro, `potential_fn` interface) runs on whitened coordinates
   $u = L^{-1}(z - \\hat z)$, $L L^T$ the Laplace covariance (plus, for a direction the data
   do not determine, the width of its bounds), where the posterior is close to a unit
   normal whenever the Laplace approximation holds: the step size is then of order one
   and the metric is the identity (the Laplace covariance is the mass matrix); the step
   size is adapted during warmup. The potential is
   $U(u) = \\chi^2(x(z))/2 - \\sum_i \\log|dx_i/dz_i|$: a flat prior on the physical value
   within the parameter's bounds unless a normal prior row is in $\\chi^2$.
3. Several chains run as one vectorised batch (`chain_method="vectorized"`), started at
   draws from the Laplace approximation, so R-hat compares chains from dispersed starts;
   their gradients come from one simulation of all chains' experiments (`_potential`).
   With several JAX devices (a CPU's cores exposed as devices, as `hertzchain fit` does:
   `hertzchain.cli.expose_cpu_cores`), the chains are split into one batch per device,
   each run in its own thread as its own program (no communication between devices).

NumPyro rather than BlackJAX: its `NUTS(potential_fn=...)` takes the fit's likelihood as
it is, adapts the step size (and, on request, a metric, with Stan's windows), vectorises
chains, and hands back divergences and tree sizes; ArviZ reads its output for R-hat, ESS
and the InferenceData file.

Diagnostics that stop a wrong answer: R-hat above `RHAT_LIMIT`, bulk or tail ESS below
`ESS_MIN`, or any divergent transition give a warning (and a non-zero exit of
`hertzchain fit --posterior --strict`). The comparison with the Laplace approximation
flags a parameter whose posterior sd, or either half of its 90 % interval, differs from
the Laplace value by more than `LAPLACE_TOLERANCE` (the covariance approximation fails
there: a bound, a banana, a skew).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np

from hertzchain.io.atomic import json_ready
from hertzchain.units import counted

from .fit import FitResult, FitWarning, fit
from .model import ForwardModel, Problem
from .parameters import (
    LabelledValues,
    from_unbounded,
    public_keys,
    public_label,
    to_unbounded,
    transform_arrays,
)
from .priors import describe

RHAT_LIMIT = 1.01
ESS_MIN = 400
LAPLACE_TOLERANCE = 0.2
# 90 % interval of a normal: +-1.6449 sd
_Z90 = 1.6448536269514722


class PosteriorWarning(UserWarning):
    """A posterior whose diagnostics fail, or whose Laplace approximation does not hold."""


@dataclasses.dataclass
class PosteriorResult:
    """Draws of the posterior and what they say.

    **Fields:**

    - `labels`, `units`: the sampled parameters (the fit's labels, registry spelling: the
      dicts below are read by either spelling, `fitting.parameters.LabelledValues`) and their
      SI units. `to_json`, the warnings and the report files name them as a user writes them
      (`eta_s`, `striker_velocity_m_s[run1]`: `fitting.parameters.public_label`).
    - `draws`: (chains, draws, p) physical values (SI).
    - `summary`: label -> mean, sd, q05, q50, q95, r_hat, ess (bulk), ess_tail.
    - `laplace`: label -> the MAP value and the Laplace sd, with the ratios to the posterior
      and whether the approximation is flagged (`fails`).
    - `sample_stats`: (chains, draws) arrays `diverging`, `num_steps`, `accept_prob`,
      `potential_energy`.
    - `divergences`, `step_size`, `elapsed_s` (fit, warmup and sampling, total),
      `gradient_evaluations`, `ess_per_second_total` (bulk ESS per second of the whole run),
      `seconds_per_effective_sample` (sampling time over the
      smallest ESS).
    - `priors`: label -> the prior each parameter carries.
    - `warnings`: failed diagnostics and Laplace flags, in words.
    - `fit`: the `FitResult` of the MAP point (its problem evaluates predictions).
    - `settings`: chains, warmup, draws, seed, target acceptance, maximum tree depth.
    """

    labels: tuple
    units: dict
    draws: np.ndarray
    summary: dict
    laplace: dict
    sample_stats: dict
    divergences: int
    step_size: float
    elapsed_s: dict
    gradient_evaluations: int
    seconds_per_effective_sample: float
    priors: dict
    warnings: list
    fit: FitResult
    settings: dict

    @property
    def problem(self) -> Problem:
        return self.fit.problem

    @property
    def passed(self) -> bool:
        """Whether R-hat, ESS and divergences all pass."""
        return not self.failed_diagnostics()

    def failed_diagnostics(self) -> list[str]:
        """What fails of R-hat < RHAT_LIMIT, ESS >= ESS_MIN and no divergences, in words."""
        failed = []
        for label, row in self.summary.items():
            if not row["r_hat"] <= RHAT_LIMIT:
                failed.append(f"R-hat of {public_label(label)} is {row['r_hat']:.4f} (> {RHAT_LIMIT})")
            ess = min(row["ess"], row["ess_tail"])
            if not ess >= ESS_MIN:
                failed.append(f"ESS of {public_label(label)} is {ess:.0f} (< {ESS_MIN})")
        if self.divergences:
            failed.append(f"{self.divergences} divergent transitions")
        return failed

    def flat_draws(self) -> np.ndarray:
        """(chains x draws, p) physical values."""
        return self.draws.reshape(-1, self.draws.shape[-1])

    def to_json(self) -> dict:
        """JSON-ready dict (SI units; non-finite numbers as null)."""
        return {
            "params": {
                public_label(label): {**{k: json_ready(v) for k, v in row.items()}, "unit": self.units[label]}
                for label, row in self.summary.items()
            },
            "laplace": {
                public_label(label): {k: (v if isinstance(v, bool) else json_ready(v)) for k, v in row.items()}
                for label, row in self.laplace.items()
            },
            "priors": {public_label(label): {k: json_ready(v) if not isinstance(v, str) else v for k, v in p.items()}
                       for label, p in self.priors.items()},
            "divergences": int(self.divergences),
            "step_size": json_ready(self.step_size),
            "mean_tree_size": json_ready(float(np.mean(self.sample_stats["num_steps"]))),
            "mean_accept_prob": json_ready(float(np.mean(self.sample_stats["accept_prob"]))),
            "gradient_evaluations": int(self.gradient_evaluations),
            "timing_s": {k: json_ready(v) for k, v in self.elapsed_s.items()},
            "seconds_per_effective_sample": json_ready(self.seconds_per_effective_sample),
            # bulk effective samples per second of the whole run (fit, compilation, warmup, sampling)
            "ess_per_second_total": {public_label(label): json_ready(row["ess"] / self.elapsed_s["total"])
                                     for label, row in self.summary.items()},
            "diagnostics_passed": self.passed,
            "failed_diagnostics": self.failed_diagnostics(),
            "warnings": list(self.warnings),
            "map": {label: json_ready(v) for label, v in public_keys(self.fit.values).items()},
            "map_reduced_chi2": json_ready(self.fit.reduced_chi2),
            "map_converged": bool(self.fit.converged),
            "map_steps": int(self.fit.n_steps),
            "settings": self.settings,
            "files": [e.trace.path or e.label for e in self.problem.experiments],
        }


def _laplace_whitening(instances, constants, x_hat, covariance):
    """(z_hat, L) with L L^T the Laplace covariance of the transformed coordinates.

    From the fit's covariance of the physical values, $\\Sigma_z = D^{-1}\\Sigma_x D^{-1}$
    with $D = \\mathrm{diag}(dx/dz)$. Directions the data and priors do not determine (the
    fit's pseudo-inverse leaves them out) get the width of the bounds: the precision is
    regularised by diag(1/h^2), h the half-width of each coordinate's bounded range.
    """
    z_hat = jnp.asarray(to_unbounded(instances, x_hat))
    _, dx_dz = jax.jvp(lambda z: from_unbounded(constants, z), (z_hat,), (jnp.ones_like(z_hat),))
    scale = np.abs(np.asarray(dx_dz))
    cov_z = np.nan_to_num(np.asarray(covariance, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
    cov_z = cov_z / np.outer(scale, scale)
    sd = np.sqrt(np.clip(np.diag(cov_z), 0.0, None))
    sd = np.where(sd > 0, sd, 1.0)
    precision = np.linalg.pinv(cov_z / np.outer(sd, sd), rcond=1e-12, hermitian=True) / np.outer(sd, sd)
    precision = precision + np.diag(1.0 / np.asarray(constants[2]) ** 2)
    values, vectors = np.linalg.eigh(0.5 * (precision + precision.T))
    chol = vectors / np.sqrt(values)[None, :]  # chol @ chol.T = precision^-1
    return z_hat, jnp.asarray(chol)


def _potential(problem: Problem, constants, z_hat, chol):
    """U(u) = chi^2/2 - sum log|dx/dz| at z = z_hat + L u (+inf where not finite).

    Its gradient, J^T r - d/du sum log|dx/dz|: the simulation is differentiated in forward
    mode (`Problem`'s custom JVP: one tangent per simulator parameter pushed through the
    time-stepping loop together with the run itself, as `fitting.fit` does for its
    Jacobian; on the CPU the C++ kernel's tangents, every chain and direction in one
    kernel run), and that Jacobian is transposed by `jax.grad`, which takes the cheap rest
    (interpolation, offsets, gains, the transforms) in reverse mode: one backward pass over
    the residuals instead of one forward pass per sampled parameter. Reverse mode through
    the integrator itself (forward run, checkpoints, adjoint back) would cost 6-13x a
    forward run for one trace loss (`benchmarks/README.md`, gradient table) against 2-4x for
    forward mode with the few parameters a posterior has.

    Chains: NumPyro's vectorised chains evaluate the gradient under `jax.vmap`. Its batching
    rule (`jax.custom_batching.custom_vmap`) evaluates the C chains' parameter vectors in
    one simulation (`Problem.residuals_many`: C x n_experiments chains on the batched
    kernel's SIMD axis) rather than C simulations; 4 chains of 10 traces of 21 beads cost
    1.5x one chain instead of 4x (274 against 180 ms on one core; `jax.vmap` of one chain's
    gradient took 714 ms).
    """

    def parts(u):  # u: (C, p) -> residuals (C, n), sum log|dx/dz| (C,)
        z = z_hat + u @ chol.T
        x, dx_dz = jax.vmap(lambda zz: jax.jvp(lambda w: from_unbounded(constants, w), (zz,),
                                                (jnp.ones_like(zz),)))(z)
        return problem.residuals_many(x), jnp.sum(jnp.log(jnp.abs(dx_dz)), axis=1)

    def value(r, log_jac):
        total = 0.5 * jnp.sum(r**2, axis=-1) - log_jac
        return jnp.where(jnp.isfinite(total), total, jnp.inf)

    def value_and_gradient_many(u):
        # The chains are independent: the gradient of the sum of their potentials is each
        # chain's own gradient. Reverse mode over the residuals' post-processing; the
        # simulation inside is differentiated by its custom JVP (the simulator's Jacobian
        # in forward mode, transposed).
        def summed(u):
            totals = value(*parts(u))
            return jnp.sum(totals), totals

        gradient, total = jax.grad(summed, has_aux=True)(u)
        return total, jnp.where(jnp.isfinite(total)[:, None], gradient, 0.0)

    # One chain's value and gradient as a jaxpr whose constants (the data, the sample
    # layout) are arguments: JAX refuses a batching rule for a function that closes over
    # arrays, and NumPyro's conditionals on per-chain predicates batch those arrays along
    # with everything else. The rule itself ignores them (they are the same for every chain).
    single = jax.make_jaxpr(lambda u: value_and_gradient_many(u[None]))(jnp.zeros(chol.shape[1]))

    @jax.custom_batching.custom_vmap
    def value_and_gradient_of(u, constants_):
        total, gradient = jax.core.eval_jaxpr(single.jaxpr, constants_, u)
        return total[0], gradient[0]

    @value_and_gradient_of.def_vmap
    def _chains(axis_size, in_batched, u, constants_):
        del constants_
        if not in_batched[0]:
            u = jnp.broadcast_to(u, (axis_size,) + u.shape)
        return value_and_gradient_many(u), (True, True)

    def value_and_gradient(u):
        return value_and_gradient_of(u, single.consts)

    @jax.custom_vjp
    def potential(u):
        return value(*parts(u[None]))[0]

    def backward(gradient, cotangent):
        return (cotangent * gradient,)

    potential.defvjp(value_and_gradient, backward)
    return potential


def _summaries(labels, draws) -> dict:
    import arviz as az

    data = az.convert_to_dataset({f"p{i}": draws[..., i] for i in range(len(labels))})
    rhat = az.rhat(data)
    ess_bulk = az.ess(data, method="bulk")
    ess_tail = az.ess(data, method="tail")
    summary = {}
    for i, label in enumerate(labels):
        flat = draws[..., i].reshape(-1)
        q05, q50, q95 = np.quantile(flat, [0.05, 0.5, 0.95])
        summary[label] = {
            "mean": float(np.mean(flat)), "sd": float(np.std(flat, ddof=1)),
            "q05": float(q05), "q50": float(q50), "q95": float(q95),
            "r_hat": float(rhat[f"p{i}"]), "ess": float(ess_bulk[f"p{i}"]),
            "ess_tail": float(ess_tail[f"p{i}"]),
        }
    return summary


def compare_with_laplace(summary: dict, values: dict, stderr: dict, *,
                         tolerance: float = LAPLACE_TOLERANCE) -> dict:
    """Per label: the posterior against the Laplace approximation (MAP +- stderr).

    Ratios of the posterior sd and of each half of the 90 % interval (q50 - q05, q95 - q50)
    to the Laplace values (stderr, 1.645 stderr); `fails` where any differs from 1 by more
    than `tolerance`, or the Laplace stderr is not finite.
    """
    out = {}
    for label, row in summary.items():
        sd = stderr[label]
        finite = math.isfinite(sd) and sd > 0
        ratios = {
            "sd_ratio": row["sd"] / sd if finite else math.nan,
            "lower_ratio": (row["q50"] - row["q05"]) / (_Z90 * sd) if finite else math.nan,
            "upper_ratio": (row["q95"] - row["q50"]) / (_Z90 * sd) if finite else math.nan,
        }
        fails = not finite or any(abs(r - 1.0) > tolerance for r in ratios.values())
        out[label] = {"map": values[label], "laplace_sd": sd, **ratios, "fails": bool(fails)}
    return out


def sample_posterior(experiments, params=("eta_s", "mu", "C"), *, priors=(), chains: int = 4,
                     warmup: int = 100, draws: int = 200, seed: int = 0, target_accept: float = 0.8,
                     max_tree_depth: int = 8, adapt_metric: bool = False,
                     forward: ForwardModel | None = None,
                     fixed=None, start=None, multistart: int = 1, progress: bool = True,
                     fit_result: FitResult | None = None) -> PosteriorResult:
    """Sample the posterior of `params` (and every parameter with a prior) by NUTS.

    **Arguments:**

    - `experiments`, `params`, `fixed`, `start`, `multistart`, `forward`: as for `fitting.fit`.
    - `priors`: tolerances (`fitting.priors`), e.g. `["bead_youngs_pa=203GPa+-4GPa",
      "sensor_gain=+-2%", "bead_radius_m=+-62.5um"]`; parameters without one are flat
      within their bounds.
    - `chains`, `warmup`, `draws`: chains (one vectorised batch per device), warmup iterations
      (step size and diagonal metric adaptation) and kept draws per chain.
    - `seed`: random seed (chain starts and the sampler).
    - `target_accept`, `max_tree_depth`: NUTS settings.
    - `adapt_metric`: also adapt a diagonal metric in the whitened coordinates during
      warmup (NumPyro's windowed schedule). Off by default: where the Laplace approximation
      holds, the whitening already makes the identity the right metric; an adapted one
      helps only where it does not hold, and needs several hundred warmup draws.
    - `progress`: progress lines of the sampler (the first device's chains) and of the fit.
    - `fit_result`: a MAP fit already made with the same problem (skips step 1).

    **Returns:** `PosteriorResult`. Warnings (`PosteriorWarning`) name failed diagnostics
    and parameters where the Laplace approximation does not hold.
    """
    if chains < 1 or warmup < 1 or draws < 2:
        raise ValueError(f"chains >= 1, warmup >= 1 and draws >= 2 needed; got {chains}, {warmup}, {draws}.")
    began = time.perf_counter()
    if fit_result is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            fit_result = fit(experiments, params, priors=priors, fixed=fixed, start=start,
                             multistart=multistart, seed=seed, covariance="noise", forward=forward,
                             progress=progress, throw=False)
    problem = fit_result.problem
    messages = []
    if not fit_result.converged:
        messages.append(f"the MAP fit did not converge ({fit_result.message}); the chains start "
                        "from where it stopped.")
    if fit_result.dof > 0 and fit_result.reduced_chi2 > 1.5:
        messages.append(
            f"reduced chi^2 = {fit_result.reduced_chi2:.3g} at the MAP point: the model does not "
            "explain the data to the stated noise, so the posterior is too narrow (look for a "
            "missing effect with `hertzchain diagnose`)."
        )
    fit_s = time.perf_counter() - began

    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    x_hat = np.asarray(fit_result.x, dtype=float)
    z_hat, chol = _laplace_whitening(problem.instances, constants, x_hat, fit_result.covariance)
    potential = _potential(problem, constants, z_hat, chol)
    p = len(problem.instances)
    key_init, key_run = jax.random.split(jax.random.PRNGKey(seed))
    starts = jnp.clip(jax.random.normal(key_init, (chains, p)), -2.0, 2.0)
    devices = jax.local_devices()[:chains]
    groups = np.array_split(np.arange(chains), len(devices))
    keys = [key_run] if len(groups) == 1 else list(jax.random.split(key_run, len(groups)))
    settings = dict(potential=potential, warmup=warmup, draws=draws, target_accept=target_accept,
                    max_tree_depth=max_tree_depth, adapt_metric=adapt_metric)
    chains_began = time.perf_counter()
    # one group of chains per device, each its own program: the devices (a CPU's cores,
    # `hertzchain.cli.expose_cpu_cores`) run them side by side, without communicating
    with ThreadPoolExecutor(len(groups)) as pool:
        futures = [pool.submit(_on_device, device, _run_chains, starts[group], key,
                               progress=progress and k == 0, **settings)
                   for k, (device, group, key) in enumerate(zip(devices, groups, keys))]
        runs = [future.result() for future in futures]
    # wall times: compilation is in the warmup; with several devices, until the last ends
    warmup_s = max(run["warmed"] for run in runs) - chains_began
    sampling_s = max(run["ended"] for run in runs) - max(run["warmed"] for run in runs)
    u = np.concatenate([run["u"] for run in runs])
    z = np.asarray(z_hat) + np.einsum("ij,cdj->cdi", np.asarray(chol), u)
    x_draws = np.asarray(jax.vmap(lambda zz: from_unbounded(constants, zz))(
        jnp.asarray(z.reshape(-1, p)))).reshape(chains, draws, p)
    stats = {k: np.concatenate([run["stats"][k] for run in runs]) for k in runs[0]["stats"]}
    labels = problem.labels
    summary = _summaries(labels, x_draws)
    laplace = compare_with_laplace(summary, fit_result.values, fit_result.stderr)
    step_size = float(np.mean(np.concatenate([run["step_size"] for run in runs])))
    gradient_evaluations = int(np.sum(stats["num_steps"]) + sum(run["warmup_steps"] for run in runs))
    smallest_ess = min(min(row["ess"], row["ess_tail"]) for row in summary.values())
    result = PosteriorResult(
        labels=labels,
        units=LabelledValues({inst.label: inst.spec.unit for inst in problem.instances}),
        draws=x_draws,
        summary=LabelledValues(summary),
        laplace=LabelledValues(laplace),
        sample_stats=stats,
        divergences=int(np.sum(stats["diverging"])),
        step_size=step_size,
        elapsed_s={"fit": fit_s, "warmup": warmup_s, "sampling": sampling_s,
                   "total": time.perf_counter() - began},
        gradient_evaluations=gradient_evaluations,
        seconds_per_effective_sample=sampling_s / smallest_ess if smallest_ess > 0 else math.inf,
        priors=LabelledValues(describe(problem.instances, problem.priors)),
        warnings=messages,
        fit=fit_result,
        settings={"chains": chains, "devices": len(groups), "warmup": warmup, "draws": draws, "seed": seed,
                  "target_accept": target_accept, "max_tree_depth": max_tree_depth,
                  "adapt_metric": adapt_metric,
                  "sampler": "numpyro NUTS, whitened by the Laplace covariance"},
    )
    failed = result.failed_diagnostics()
    if failed:
        result.warnings.append(
            "the sampler's diagnostics fail (" + "; ".join(failed) + "): do not trust these "
            "numbers; run more warmup and draws, or more chains."
        )
    flagged = [label for label, row in laplace.items() if row["fails"]]
    if flagged:
        worst = ", ".join(
            f"{public_label(label)} (sd x{laplace[label]['sd_ratio']:.2f}, 90 % interval halves "
            f"x{laplace[label]['lower_ratio']:.2f}/x{laplace[label]['upper_ratio']:.2f})"
            for label in flagged
        )
        result.warnings.append(
            f"the covariance (Laplace) approximation fails for {worst}: quote the posterior's "
            "intervals, not the fit's standard errors."
        )
    for text in result.warnings:
        warnings.warn(text, PosteriorWarning, stacklevel=2)
    return result


def _run_chains(starts, key, *, potential, warmup, draws, target_accept, max_tree_depth, adapt_metric,
                progress) -> dict:
    """NUTS (NumPyro's kernel) from `starts` (chains, p), the chains as one vectorised batch: the
    whitened draws (chains, draws, p), sample statistics, step sizes, the warmup's tree
    sizes and when the warmup and the sampling ended (`time.perf_counter`).

    The iterations are driven here, one compiled NUTS iteration called `warmup + draws` times,
    rather than by `numpyro.infer.MCMC`, which compiles its loop once for the warmup and
    again for the draws (a compilation of the whole iteration, gradient included: seconds
    per device). It is the same kernel (`_nuts`: the chains' keys split as MCMC splits them,
    the state's iteration count switching the adaptation off after the warmup), so the
    draws are MCMC's draw for draw (`tests/test_posterior.py`). The chains run in lockstep
    (`_lockstep_axes`), so the adaptation's branches are taken, not both evaluated.
    """
    from hertzchain.progress import Progress

    chains = starts.shape[0]
    init, step = _nuts(potential, warmup=warmup, target_accept=target_accept,
                       max_tree_depth=max_tree_depth, adapt_metric=adapt_metric)
    if chains > 1:
        state = jax.jit(jax.vmap(init))(starts, jax.random.split(key, chains))
        axes = _lockstep_axes(state)
        state = _shared_fields(state)
        iterate = jax.jit(jax.vmap(step, in_axes=(axes,), out_axes=axes))
    else:
        state = jax.jit(init)(starts[0], key)
        iterate = jax.jit(step)
    report = Progress(warmup + draws, f"NUTS, {counted(chains, 'chain')}, {warmup} warmup + {draws} draws") \
        if progress else None
    fields = ("z", "num_steps", "diverging", "accept_prob", "potential_energy")
    warmup_steps, records = [], []
    warmed = None
    for i in range(warmup + draws):
        state = iterate(state)
        if i < warmup:
            warmup_steps.append(state.num_steps)
        else:
            records.append(tuple(getattr(state, name) for name in fields))
        if i == warmup - 1:
            jax.block_until_ready(state)
            warmed = time.perf_counter()
        if report is not None:
            report.advance()
    def by_chain(column):  # one field's values of every draw: (chains, draws, ...)
        values = np.asarray(jnp.stack(column))
        return np.swapaxes(values if chains > 1 else values[:, None], 0, 1)

    u, *columns = (by_chain(column) for column in zip(*records))
    stats = {name: column.reshape(chains, draws) for name, column in zip(fields[1:], columns)}
    return {"u": u.reshape(chains, draws, -1), "stats": stats, "step_size": np.asarray(state.adapt_state.step_size).reshape(-1),
            "warmup_steps": int(np.sum(np.asarray(jnp.stack(warmup_steps)))),
            "warmed": warmed, "ended": time.perf_counter()}


def _nuts(potential, *, warmup: int, target_accept: float, max_tree_depth: int, adapt_metric: bool):
    """NumPyro's NUTS for one chain through its functional interface (`numpyro.infer.hmc.hmc`):
    `init(start, key)`, the chain's first state as `NUTS.init` makes it (the potential and
    its gradient at `start`, the heuristic step size; the key split as `NUTS.init` splits it),
    and `step(state)`, one iteration (`NUTS.sample`). `init` must be traced before `step`:
    it sets the kernel's warmup length and tree depth.

    Compiled by the caller: run eagerly, `init` dispatches and compiles each operation of the
    potential's gradient on its own (11-13 s a device for the benchmark's posterior);
    compiled, the start's gradient is evaluated as every later step's is, where the eager
    one differed from it by round-off, 4e-12 of itself
    (`tests/test_posterior.py::test_compiled_sampler_start_equals_numpyros_eager_start`)."""
    from numpyro.infer.hmc import hmc

    init_kernel, sample_kernel = hmc(potential_fn=potential, algo="NUTS")

    def init(start, key):
        key, _ = jax.random.split(key)  # `NUTS.init` splits off a key for a model (none here)
        return init_kernel(start, num_warmup=warmup, adapt_mass_matrix=adapt_metric, dense_mass=False,
                           target_accept_prob=target_accept, max_tree_depth=max_tree_depth,
                           find_heuristic_step_size=True, rng_key=key)

    return init, lambda state: sample_kernel(state, (), {})


def _lockstep_axes(state):
    """`jax.vmap` axes of a vectorised NUTS state: 0 for every field but the two the chains of a
    batch share, the iteration count and the adaptation window it selects (None).

    Why: NumPyro's iteration branches on the iteration count (adapt or not; at the end of an
    adaptation window, search a new step size). With the count batched, as `NUTS.sample`
    vectorises it, `vmap` turns each branch into a select that evaluates both sides: the
    step-size search, with its leapfrog steps and gradients, ran at every iteration, draws
    included, and was thrown away (about one gradient in seven of the benchmark's posterior).
    Shared, the branches stay branches; the values taken are the same."""
    axes = jax.tree_util.tree_map(lambda _: 0, state)
    return axes._replace(i=None, adapt_state=axes.adapt_state._replace(window_idx=None))


def _shared_fields(state):
    """A vectorised NUTS state with its iteration count and adaptation window as one value
    (every chain's is the same)."""
    window = state.adapt_state.window_idx
    for name, value in (("i", state.i), ("window_idx", window)):
        if not bool(jnp.all(value == value[0])):
            raise RuntimeError(f"NUTS chains of one batch out of step: {name} = {np.asarray(value)}")
    return state._replace(i=state.i[0], adapt_state=state.adapt_state._replace(window_idx=window[0]))


def _on_device(device, function, *args, **kwargs):
    """`function(*args, **kwargs)` with `device` as JAX's default (this thread only)."""
    with jax.default_device(device):
        return function(*args, **kwargs)


def posterior_predictive(result: PosteriorResult, *, n_draws: int = 100, seed: int = 0,
                         quantiles=(0.05, 0.5, 0.95)) -> list[dict]:
    """Per file, channel -> (len(quantiles), n_samples) quantiles of the model over
    `n_draws` posterior draws (the model's spread; the noise is not added)."""
    flat = result.flat_draws()
    rng = np.random.default_rng(seed)
    chosen = flat[rng.choice(len(flat), size=min(n_draws, len(flat)), replace=False)]
    problem = result.problem
    model = jax.jit(problem.model_many)
    rows = [np.asarray(model(jnp.asarray(block))) for block in np.array_split(chosen, max(1, len(chosen) // 16))]
    models = np.concatenate(rows)
    bands = np.quantile(models, quantiles, axis=0)
    out = []
    start = 0
    for experiment in problem.experiments:
        entry = {}
        for name in experiment.channels:
            n = len(experiment.time_s)
            entry[name] = bands[:, start:start + n]
            start += n
        out.append(entry)
    return out
