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

The package, one concept a module: `plan` (plans, their Fisher information and predicted
errors: `design`, `plan_experiments`), `optimization` (`optimize_plan`), `scatter`
(`fit_scatter`: the check against actual fits) and `plot` (`plot_design`).
"""

from .optimization import PlanOptimization, optimize_plan  # noqa: F401
from .plan import CRITERIA, NUISANCES, DesignError, DesignResult, design, plan_experiments  # noqa: F401
from .plot import plot_design  # noqa: F401
from .scatter import FitScatter, fit_scatter  # noqa: F401
