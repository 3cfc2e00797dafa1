"""Find where a chain model and measured traces disagree, name the missing effect, add it,
and repeat until nothing significant is left.

`diagnose(experiments)` runs this workflow:

1. **Base fit.** The stated model (default: the header's dissipationless Hertz chain with
   ideal force sensors) is fitted with its nuisances free: per file the striker velocity
   and the trigger offset (optionally a gain per channel), plus any physical parameter the
   user frees. A disagreement is then not just a badly chosen nuisance.
2. **Locate** (`fitting.diagnosis.locate`): the whitened residual by channel x time window, by file
   (amplitude) and by frequency band.
3. **Screen and refit.** Every candidate of the library (`fitting.effects`) is ranked by
   its score (the $\\chi^2$ a Gauss-Newton step on its strength alone would remove, from
   the Jacobian at the current fit, projected off the free parameters; a strength whose
   law is off at the fit, such as the contact exponent on Hertz contacts, has no derivative
   there and is scored by its secants, together with the candidate's other columns) and
   then refitted with its strength(s) free, from the start values whose secant removes the most
   $\\chi^2$ (a grid of resonance frequencies for `sensor_dynamics`, whose misfit is
   multimodal in f0: the three best are refitted) and from fresh nuisances (a base fit
   pays for a missing effect with its nuisances, which can leave them in a basin the
   candidate's optimum is not reached from); per-bead radii (`bead_dispersion`) are
   fitted by time-window continuation (records cut at 45 and 70 % of their length, a
   few loose steps each, then whole), since from zero a fit of all radii on whole records
   stops in a local minimum. Candidates whose sensitivity lies in the span of the free
   parameters are reported as not separable (a uniform stiffness scale with both striker
   velocity and gain free: F(t; l kappa, V0) = l^-2 F(t; kappa, l^2 V0), tested in
   `tests/test_fit_identifiability.py`). Candidates are refitted in order
   of their number of strengths; once one explains the misfit to the noise level,
   candidates with more strengths are not refitted (they could only fit the noise better:
   parsimony, and the per-bead refit is the costliest step of a diagnosis). The best
   `max_refits` candidates by score are always refitted: a linear score misjudges effects
   with a threshold or a singular onset (plasticity, precompression, friction), whose
   starts span their physical range instead (`_Search.start_for`); so is, whatever its
   rank, every candidate whose score alone would bring the chi^2 excess into the noise
   band (the rank orders the refits, it does not drop what a fit of one candidate would
   find). A round whose misfit is already at the noise level refits nothing, and screens
   nothing either (the scores would rank what is not needed).
4. **Decide.** A candidate with k strengths is named only if all hold:
   (a) its $\\Delta\\chi^2$ beats the BIC penalty $k\\ln n$;
   (b) it removes at least `min_share` of the excess misfit $\\chi^2 - \\mathrm{dof}$ that
   remains (practical significance: with 10^4 samples every small convention difference is
   statistically significant);
   (c) it improves held-out traces: two-fold cross-validation over files (folds alternate
   in amplitude), the global parameters fitted on one fold, the other fold's nuisances
   refitted with them held, both by one Levenberg-Marquardt step from the fit to all files
   (approximate cross-validation, `_Search.heldout_chi2`); the summed held-out $\\chi^2$
   must drop by more than k (k ln n for a candidate with more than `FEW_STRENGTHS`
   strengths, which is moreover named only for an excess of at least `PRACTICAL_GAP` per
   degree of freedom; otherwise it is reported as "possible, not needed").
   Held-out log-likelihood rather than an approximate (Laplace) evidence: the evidence
   depends on prior widths of strengths no lab states, while the held-out check asks
   directly whether an effect fitted on some shots predicts the others.
   Among the candidates that pass, the one with the largest held-out gain is named.
   Nothing is named when the excess is already within the noise band or when no
   candidate passes. The band is `NOISE_BAND_SIGMA` standard deviations of $\\chi^2$ for a
   model that holds: $\\sqrt{2\\,\\mathrm{dof}}$ from the samples' noise, and, for a
   channel whose noise level was estimated from $m$ samples (the importer's pre-trigger
   segment, `x_import_<channel>_noise_samples`), the spread that estimate adds: its $n$
   samples' $\\chi^2$ scale by $\\sigma^2/\\hat\\sigma^2$, of relative variance
   $2/(m-1)$, so $2n^2/(m-1)$ joins the variance (`_Search.noise_estimate_variance`).
5. **Iterate**: the named effect joins the model and the search repeats (`max_effects`).
   A **backward check** then refits without each named effect and drops any that no longer
   passes (a) and (b). A **misspecification alarm** is raised when the final excess is
   still above the noise band: the residual that remains is reported (where and how
   large) without a name.

All fits share one compiled forward model and Jacobian (every candidate strength is a
parameter of it, held at 0 when off), so the whole diagnosis compiles the simulator once,
twice when `plasticity` is tried: points where its strength is 0 run on Hertz contacts, the
same model there at a quarter of the cost of the elastic-plastic contact law (`_Evaluator`,
which also computes only the Jacobian columns a fit frees, caches recent points, and takes
the residuals and the predictions `locate` reads from one compiled model vector per variant
of the law: compilation, not simulation, is most of a diagnosis's time). The
fits are `fitting.fit`'s Levenberg-Marquardt (`fitting.fit.least_squares`: optimistix with
the fit's termination and test of an optimum) on the evaluator's residuals, with columns
freed or held, rows weighted in or out (the time windows of `bead_dispersion`) and points
clipped to the parameters' bounds (`_Bounded`); the held-out check's step
(`_Search._damped_step`) is one damped Gauss-Newton step, not a fit.

The package, one concept a module: `protocol` (the rules' numbers, the model string),
`evaluator` (residuals on the cheapest equivalent model), `results` (`CandidateResult`,
`Step`, `Diagnosis`); `search` (the state the steps share) joined by `refits`, `candidates`
(starts and interpretation), `screening` and `heldout`; `workflow` (`diagnose`, the rounds)
joined by `verdict` (the noise band, the tests, the alarm's conclusion) and `report`.
"""

from ..fit import least_squares  # noqa: F401  (the optimiser every fit of a diagnosis reads from here)
from .evaluator import _Bounded, _Evaluator  # noqa: F401
from .protocol import (  # noqa: F401
    FEW_STRENGTHS,
    LOCAL_BAND_SIGMA,
    MIN_SHARE,
    NOISE_BAND_SIGMA,
    NUISANCES,
    PRACTICAL_GAP,
    PRELOAD_START_FRACTIONS,
    REFIT_STARTS,
    SENSOR_START_F0_HZ,
    WINDOW_FRACTIONS,
    WINDOW_MAX_STEPS,
    WINDOW_TOLERANCE,
    YIELD_START_FRACTIONS,
    DiagnosisError,
    noise_estimate_variance,
    parse_model,
)
from .results import CandidateResult, Diagnosis, Step  # noqa: F401
from .search import _Search  # noqa: F401
from .workflow import _Workflow, diagnose  # noqa: F401
