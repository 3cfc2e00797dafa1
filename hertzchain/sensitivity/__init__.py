"""Exact local and global sensitivities of physical observables to physical parameters.

Every derivative here is taken by automatic differentiation through the velocity-Verlet
core (`hertzchain.solve`): no finite differences. The run's time grid (step, sampling,
length) is fixed before differentiating, so a derivative is that of the simulator on that
grid, and central finite differences of the simulator on the same grid agree with it
(tests/test_sensitivity.py).

**Parameters** (`PARAMETERS`, the registry of `hertzchain.parameters`, by their public
names; SI units): `eta_s`, `mu`, `mu_star`, `striker_velocity_m_s`, `striker_mass_kg`,
`wall_youngs_pa`, `wall_poisson`, `bead_radius_m`, `bead_density_kg_m3`, `bead_youngs_pa`,
`bead_poisson`, `sensor_beta`, `sensor_f0_hz`, `precompression_n` (at a positive preload:
at zero the static overlap F^(2/3) makes the derivative singular), `bead_yield_stress_pa`
and `yield_force_n` for elastic-plastic contacts (`plasticity=True`), and `bead_masses_kg`
(one per bead: N parameters). The previous short names (`eta`, `wall_youngs`) are read too,
each with one `ParameterNameWarning` naming the argument it was given in and the name to
write; every result names a parameter by its public name.

**Observables** (`observable_names`), with `CH` one of `contact_K`, `wall`, `sensor_K`:

- `CH_peak` (N): the peak of the incident pulse: the first local maximum of the trace above
  30 % of its height above the static preload (`peaks.first_peak_index`; for `wall`: the
  largest value), refined by the parabola through the three samples around it
  (`peaks.refine_peak`). The parabola's vertex value is a smooth function of the samples,
  so its derivative is that of the interpolated peak (the envelope theorem), not of an
  array index.
- `CH_peak_time` (s): the vertex time of that parabola.
- `CH_arrival` (s): the arrival time of the pulse: the time at which its leading edge
  crosses half its height above the static preload, linearly interpolated between the
  two samples around the crossing.
- `CH_duration` (s): the pulse duration $2\\tau$ of the paper's $F_m\\cos^6((t-t_0)/\\tau)$,
  estimated from the full width at half height as FWHM / arccos(2^{-1/6}) (exact for a
  cos^6 pulse; the discrete chain's pulse gives about 1.5 % less than a cos^6 fit).
- `speed_K_L` (m/s): pulse speed from contact K to contact L (K < L): the distance between
  the contact points at rest over the difference of their arrival times.
- `force_ratio_K`: wall peak over the incident peak at contact K (Eq. 5 of the paper).
- `dissipated_viscous`, `dissipated_friction`, `dissipated_plastic`, `dissipated_total`
  (J): energy dissipated by each mechanism by the end of the record.
- `trace_CH` (N, one value per sample): the whole force trace.

Elasticities ($\\partial\\ln O/\\partial\\ln p$) and their conventions for zero values and
whole traces: `hertzchain.sensitivity.result`.

Track friction is exact Coulomb stick-slip in the core (a clamped kick per step), so a
quantity is piecewise smooth at the scale of one time step: wherever beads stick, slip,
stop or touch again. Derivatives are exact on each piece; finite differences agree with
them to about 1e-3 along the incident pulse (tests), less well for quantities that sum
many late stick/slip events (the friction energy after the beads have stopped and
re-collided).

Forward or reverse mode is chosen from the Jacobian's shape: reverse (`jax.jacrev`) when
there are fewer observable values than parameter values (e.g. per-bead masses), forward
(`jax.jacfwd`) otherwise.

Modules: `observables` (names, parsing, values from traces), `jacobian` (the AD
Jacobian), `result` (`SensitivityResult`), `local` (`sensitivity` at one setup), `sweep`
(`sensitivity_sweep` over a grid of setups), `global_measures` (`global_sensitivity`
over a box), `plots`.
"""

from ..parameters import (
    PARAMETERS as PARAMETERS,
    Parameter as Parameter,
    parameter_values as parameter_values,
    with_parameters as with_parameters,
)
from .global_measures import (
    GlobalSensitivity as GlobalSensitivity,
    global_sensitivity as global_sensitivity,
)
from .jacobian import (
    choose_mode as choose_mode,
    jacobian_at as jacobian_at,
    observable_function as observable_function,
)
from .local import sensitivity as sensitivity
from .observables import (
    OBSERVABLE_FORMS as OBSERVABLE_FORMS,
    Observable as Observable,
    evaluate_observables as evaluate_observables,
    observable_names as observable_names,
    parse_observable as parse_observable,
)
from .plots import (
    plot_elasticities as plot_elasticities,
    plot_global_ranking as plot_global_ranking,
    plot_sweep as plot_sweep,
    plot_trace_sensitivities as plot_trace_sensitivities,
)
from .result import SensitivityResult as SensitivityResult
from .sweep import sensitivity_sweep as sensitivity_sweep
