"""The registry of fittable parameters: names, units, scopes, transforms, bounds, and how
each one acts on a `ChainSetup` or on the measurement (a nuisance).

Every parameter is optimised in a transformed coordinate $z$: first the physical value
$x$ is mapped to

- $s = \\log x$ (`space="log"`, where positivity is physical and zero is not: moduli,
  velocities, C, gains),
- $s = \\operatorname{asinh}(x/\\mathrm{scale})$ with $x = \\mathrm{scale}\\,|\\sinh s|$
  (`space="asinh"`, for non-negative quantities whose zero is physical: eta, mu,
  precompression): logarithmic above `scale`, linear through zero, so a fit can reach and
  leave zero (a log coordinate would send a vanishing parameter infinitely far away, where
  its gradient vanishes and the optimiser stalls),
- $s = x/\\mathrm{scale}$ (`space="linear"`),

then the bounds $[s_{lo}, s_{hi}]$ are enforced by $s = c + h\\tanh((z - c)/h)$ with $c$,
$h$ the centre and half-width of the bounds. Near the centre $z \\approx s$, so optimisation
steps are in log units or in units of `scale`; $z$ is unbounded, so the optimiser never
leaves the physical range.

Scopes:

- `"global"`: one value shared by every experiment (eta, mu, C, ...).
- `"experiment"`: one value per trace file (striker velocity, trigger time offset).
- `"channel"`: one value per recorded channel of each file (a gain per shot and channel).
- `"sensor"`: one value per channel name, shared by every file that records it (the
  calibration of one physical sensor used for all shots).

Kinds (what a value acts on):

- `"setup"`: a field of the `ChainSetup` (through `ParameterSpec.apply`; a name that
  `hertzchain.parameters` also has is set and read by that registry's `set` and `get`).
- `"time_offset"`: the model is compared with the data at $t - t_{off}$, i.e. the data's
  clock reads $t_{off}$ at the impact.
- `"gain"`: the data channel is modelled as gain x the simulated force.
- `"extra"`: a value handed to a custom forward model in its `extras` dict (model
  switches for effects the core solver does not have; see `fitting.model.ForwardModel`).

Names: each parameter has one name a user sees (`ParameterSpec.public_name`: command-line
options, experiment files, `fit.json`, reports, plots), the unit-suffixed spelling of the
`ChainSetup` field it sets (`eta_s`, `wall_youngs_pa`, `striker_velocity_m_s`,
`precompression_n`, `bead_youngs_pa`, `bead_radius_m`, and `time_offset_s`); dimensionless
ones keep theirs (`mu`, `mu_star`, `wall_poisson`, `gain`, `sensor_gain`), and so does `C`,
the paper's symbol of the speed constant in $v = C F_m^{1/6}$, whose unit (m/s N^-1/6) no
suffix spells readably (every output states it in its unit column). The registry keys
(`ParameterSpec.name`: `eta`, `wall_youngs`, ...) are the internal names; `resolve_name`
maps either spelling to the key (the short one, the previous public name, warns once, one
line: `ParameterNameWarning`), `public_label` maps a key or an instance label to what a user
sees. Every function that takes parameter names from its caller (`fitting.fit`,
`make_problem`, `fitting.design`, `fitting.priors`, `diagnose`, ...) resolves them so; code
holding keys looks them up (`REGISTRY`, `get_spec`, `checked_keys`) and hands public names
to those functions, so only a user's spelling warns.

Add parameters with `register_parameter`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from hertzchain import contact
from hertzchain.chain import ChainSetup
from hertzchain.parameters import PARAMETERS as SETUP_PARAMETERS
from hertzchain.parameters import ParameterNameWarning, relabel, resolve_key  # noqa: F401 (the warning: one class for both registries)
from hertzchain.theory import LONG_WAVE_SPEED_FACTOR, discrete_velocity_constant

SCOPES = ("global", "experiment", "channel", "sensor")
SPACES = ("log", "asinh", "linear")
KINDS = ("setup", "time_offset", "gain", "extra")

# Speed constant of the discrete chain's solitary wave in lattice units,
# v = DISCRETE_SPEED_FACTOR * 2R kappa^(1/3) m^(-1/2) F_m^(1/6), and Nesterenko's long-wave
# (continuum) value of the same factor, 2/sqrt(5) (Eq. 3 of the paper): see hertzchain.theory.
CONTINUUM_SPEED_FACTOR = LONG_WAVE_SPEED_FACTOR


@dataclasses.dataclass(frozen=True)
class ParameterSpec:
    """One fittable parameter.

    **Fields:**

    - `name`: the registry key, the name internal code uses (`eta`, `wall_youngs`).
    - `public_name`: the one name a user sees and writes (command line, experiment files,
      fit.json, reports): `eta_s`, `wall_youngs_pa` (default: `name`).
    - `unit`: SI unit of the value (`""` if dimensionless).
    - `scope`: `"global"`, `"experiment"` or `"channel"`.
    - `space`: `"log"` (positive values, optimised in log), `"asinh"` (non-negative values
      whose zero is physical) or `"linear"`.
    - `lower`, `upper`: bounds of the physical value (SI); `"asinh"` needs lower = 0.
    - `scale`: for `"linear"` parameters the size of one optimisation unit, for `"asinh"`
      the value where the coordinate turns from linear to logarithmic (SI).
    - `kind`: `"setup"`, `"time_offset"`, `"gain"` or `"extra"`.
    - `apply`: `(setup, value) -> setup` for `kind="setup"` (pure, differentiable).
    - `read`: `(setup) -> value`: the value a setup already has (default start), or None.
    - `default`: start value when `read` is None (nuisances: offset 0, gain 1).
    - `description`: one line for help texts.
    - `stage`: order in which setup parameters are applied: 0 for quantities of the
      materials and the geometry, 1 for those defined relative to them (C sets the
      stiffness scale so that the chain with its current beads has speed constant C, so a
      free bead modulus or radius must be applied before it).
    """

    name: str
    unit: str
    scope: str
    space: str
    lower: float
    upper: float
    kind: str = "setup"
    scale: float = 1.0
    apply: Callable | None = None
    read: Callable | None = None
    default: float = float("nan")
    description: str = ""
    stage: int = 0
    public_name: str = ""

    def __post_init__(self):
        if not self.public_name:
            object.__setattr__(self, "public_name", self.name)
        if self.scope not in SCOPES:
            raise ValueError(f"ParameterSpec {self.name}: scope must be one of {SCOPES}.")
        if self.space not in SPACES:
            raise ValueError(f"ParameterSpec {self.name}: space must be one of {SPACES}.")
        if self.kind not in KINDS:
            raise ValueError(f"ParameterSpec {self.name}: kind must be one of {KINDS}.")
        if not self.lower < self.upper:
            raise ValueError(f"ParameterSpec {self.name}: lower must be below upper.")
        if self.space == "log" and not self.lower > 0:
            raise ValueError(f"ParameterSpec {self.name}: a log parameter needs lower > 0.")
        if self.space == "asinh" and self.lower != 0:
            raise ValueError(f"ParameterSpec {self.name}: an asinh parameter needs lower = 0.")
        if self.kind == "setup" and self.apply is None:
            raise ValueError(f"ParameterSpec {self.name}: a setup parameter needs `apply`.")

    # --- the transform, elementwise, usable on numpy or jax arrays -------------------------
    def _s_bounds(self) -> tuple[float, float]:
        if self.space == "log":
            return math.log(self.lower), math.log(self.upper)
        if self.space == "asinh":  # symmetric, so that zero sits at the centre
            top = math.asinh(self.upper / self.scale)
            return -top, top
        return self.lower / self.scale, self.upper / self.scale

    def transform_constants(self) -> tuple[float, float, float, float]:
        """(space code 0 log / 1 asinh / 2 linear, centre c, half-width h, scale)."""
        lo, hi = self._s_bounds()
        return float(SPACES.index(self.space)), 0.5 * (lo + hi), 0.5 * (hi - lo), self.scale

    def to_s(self, value: float) -> float:
        if self.space == "log":
            return math.log(value)
        if self.space == "asinh":
            return math.asinh(value / self.scale)
        return value / self.scale

    def in_bounds(self, value: float) -> bool:
        if self.space == "asinh":
            return self.lower <= value < self.upper
        return self.lower < value < self.upper


def _apply(name: str):
    """The setter of `hertzchain.parameters` for `name` (a pure, differentiable setup update)."""
    return SETUP_PARAMETERS[name].set


def _read(name: str):
    """The getter of `hertzchain.parameters` for `name`, as a Python float."""
    get = SETUP_PARAMETERS[name].get
    return lambda setup: float(np.asarray(get(setup)))


def bare_speed_constant(setup: ChainSetup) -> float:
    """Discrete-chain speed constant without thwarted rotation (mu* = 0), SI.

    $C_0 = 0.905516\\,2R\\,\\kappa^{1/3} m^{-1/2}$ for bead 1 on a bead identical to it
    (201.385 for the paper's beads), in the units of $v = C F_m^{1/6}$ (v in m/s, F_m in N).
    """
    radius = setup.bead_radius_m[0]
    kappa = contact.kappa_sphere_sphere(
        radius, setup.bead_youngs_pa[0], setup.bead_poisson[0],
        radius, setup.bead_youngs_pa[0], setup.bead_poisson[0],
    )
    return discrete_velocity_constant(radius, setup.bead_mass_kg[0], kappa)


def _apply_speed_constant(setup: ChainSetup, value):
    """Set the stiffness scale so that the chain's discrete speed constant is `value`."""
    one_plus = (value / bare_speed_constant(setup)) ** 3
    return eqx.tree_at(lambda s: s.mu_star, setup, one_plus - 1.0)


def _read_speed_constant(setup: ChainSetup) -> float:
    return float(bare_speed_constant(setup) * (1.0 + setup.mu_star) ** (1.0 / 3.0))


def _read_wall_youngs(setup: ChainSetup) -> float:
    return min(_read("wall_youngs")(setup), 1e12)  # a rigid wall starts as a very stiff one


REGISTRY: dict[str, ParameterSpec] = {}


# public name -> registry key, for the names that differ
_KEY_OF_PUBLIC: dict[str, str] = {}


def register_parameter(spec: ParameterSpec, *, replace: bool = False) -> ParameterSpec:
    """Add a parameter to the registry (e.g. the strength of a new model effect)."""
    taken = spec.name in REGISTRY or spec.public_name in _KEY_OF_PUBLIC
    if taken and not replace:
        raise ValueError(f"A parameter named {spec.name!r} is already registered.")
    REGISTRY[spec.name] = spec
    if spec.public_name != spec.name:
        _KEY_OF_PUBLIC[spec.public_name] = spec.name
    return spec


def public_names() -> tuple[str, ...]:
    """The names a user writes, one per registered parameter, in registry order."""
    return tuple(spec.public_name for spec in REGISTRY.values())


def resolve_name(name: str, *, where: str | None = None) -> str:
    """The registry key of the parameter a user named `name`, written either way: its public
    name (`wall_youngs_pa`) or its previous, short one (`wall_youngs`), which warns once, one
    line (`ParameterNameWarning`), with the name to write and `where` (the argument, option or
    file it was written in: `fixed`, `--fixed`) where given. An unknown name raises a
    ValueError listing the public names."""
    return resolve_key(
        name, _KEY_OF_PUBLIC, lambda key: REGISTRY[key].public_name if key in REGISTRY else None, where,
        lambda: ValueError(f"Unknown parameter {name!r}{f' in {where}' if where else ''}. "
                           f"Fittable parameters: {', '.join(public_names())}."))


def resolve_label(label: str, *, where: str | None = None) -> str:
    """`resolve_name` of a label's parameter, the instance kept: `striker_velocity_m_s[run1]`
    -> `striker_velocity[run1]`."""
    return relabel(label, lambda name: resolve_name(name, where=where))


class LabelledValues(dict):
    """label -> value (a fit's values, errors, units), read by either spelling of a
    parameter: `values["eta_s"]` and `values["eta"]` are the same entry, as are
    `striker_velocity_m_s[run1]` and `striker_velocity[run1]`. Keys are stored in registry
    spelling (`FitResult.labels`); iteration and `to_json` are unchanged."""

    def _key(self, label):
        if not isinstance(label, str) or dict.__contains__(self, label):
            return label
        return relabel(label, lambda name: _KEY_OF_PUBLIC.get(name, name))

    def __getitem__(self, label):
        return dict.__getitem__(self, self._key(label))

    def __contains__(self, label) -> bool:
        return dict.__contains__(self, self._key(label))

    def get(self, label, default=None):
        return dict.get(self, self._key(label), default)


def public_label(label: str) -> str:
    """What a user sees for a registry key or instance label: `eta` -> `eta_s`,
    `striker_velocity[run1]` -> `striker_velocity_m_s[run1]`; other names unchanged."""
    return relabel(label, lambda name: REGISTRY[name].public_name if name in REGISTRY else name)


def public_keys(values: dict) -> dict:
    """`values` (label -> anything) keyed by what a user sees (`public_label`), for files."""
    return {public_label(label): value for label, value in values.items()}


for _spec in (
    ParameterSpec(
        "eta", "s", "global", "asinh", 0.0, 1e-3, public_name="eta_s", scale=1e-8, apply=_apply("eta"),
        read=_read("eta"),
        description="viscoelastic time eta of F_v = eta kappa d(delta^3/2)/dt (s)",
    ),
    ParameterSpec(
        "mu", "", "global", "asinh", 0.0, 3.0, scale=1e-4, apply=_apply("mu"),
        read=_read("mu"),
        description="friction coefficient of the beads on the track",
    ),
    ParameterSpec(
        "C", "m/s N^-1/6", "global", "log", 20.0, 2000.0, apply=_apply_speed_constant,
        read=_read_speed_constant, stage=1,
        description="speed constant of the chain's solitary waves, v = C F_m^(1/6), set "
        "through the stiffness scale kappa* = (1+mu*) kappa (C proportional to (1+mu*)^(1/3))",
    ),
    ParameterSpec(
        "mu_star", "", "global", "linear", -0.5, 1.0, scale=0.01, apply=_apply("mu_star"),
        read=_read("mu_star"), stage=1,
        description="thwarted-rotation friction, kappa* = (1+mu*) kappa (same physics as C)",
    ),
    ParameterSpec(
        "wall_youngs", "Pa", "global", "log", 1e6, 1e13, public_name="wall_youngs_pa", apply=_apply("wall_youngs"),
        read=_read_wall_youngs, description="Young's modulus of the wall (Pa)",
    ),
    ParameterSpec(
        "wall_poisson", "", "global", "linear", -0.9, 0.499, scale=0.1,
        apply=_apply("wall_poisson"), read=_read("wall_poisson"),
        description="Poisson ratio of the wall",
    ),
    ParameterSpec(
        "precompression", "N", "global", "asinh", 0.0, 1e4, public_name="precompression_n", scale=1e-3,
        apply=_apply("precompression"),
        read=_read("precompression"), description="static preload pressing the chain (N)",
    ),
    ParameterSpec(
        "bead_youngs", "Pa", "global", "log", 1e6, 1e13, public_name="bead_youngs_pa", apply=_apply("bead_youngs"),
        read=_read("bead_youngs"),
        description="Young's modulus of the chain's beads (Pa; all beads scaled together, the "
        "striker keeps its own)",
    ),
    ParameterSpec(
        "bead_radius", "m", "global", "log", 1e-5, 1.0, public_name="bead_radius_m", apply=_apply("bead_radius"),
        read=_read("bead_radius"),
        description="radius of the chain's beads (m; all beads scaled together at their density, "
        "so the mass follows R^3; the striker keeps its own)",
    ),
    ParameterSpec(
        "striker_velocity", "m/s", "experiment", "log", 1e-4, 50.0, public_name="striker_velocity_m_s",
        apply=_apply("striker_velocity"), read=_read("striker_velocity"),
        description="impact velocity of each file (m/s)",
    ),
    ParameterSpec(
        "time_offset", "s", "experiment", "linear", -5e-5, 5e-5, public_name="time_offset_s", kind="time_offset", scale=1e-6,
        default=0.0,
        description="trigger delay of each file: the data clock reads time_offset at the impact (s)",
    ),
    ParameterSpec(
        "gain", "", "channel", "log", 0.05, 20.0, kind="gain", default=1.0,
        description="calibration factor of each channel of each file: data = gain x force",
    ),
    ParameterSpec(
        "sensor_gain", "", "sensor", "log", 0.05, 20.0, kind="gain", default=1.0,
        description="calibration factor of each sensor (channel name), shared by every file "
        "that records it: data = gain x force",
    ),
):
    register_parameter(_spec)

# Parameters that describe the same physical quantity: only one of each group may be fitted.
EXCLUSIVE = ((("C", "mu_star"), "the same stiffness scale"), (("gain", "sensor_gain"), "the same calibration"))


def get_spec(name: str) -> ParameterSpec:
    """The registered parameter `name`, a name the code holds: a registry key or a public name
    (not resolved as a user's spelling, so nothing warns); an unknown name raises a ValueError
    listing all."""
    return REGISTRY[name] if name in REGISTRY else REGISTRY[resolve_name(name)]


def parse_parameter_list(text_or_names, *, where: str | None = None) -> tuple[str, ...]:
    """Parse `"eta_s,mu,C"` (or a sequence of names, either spelling: a previous name warns,
    `resolve_name`) into registry keys checked by `checked_keys`; `where` as in
    `resolve_name`."""
    if isinstance(text_or_names, str):
        names = [part.strip() for part in text_or_names.split(",") if part.strip()]
    else:
        names = [str(part).strip() for part in text_or_names]
    if not names:
        raise ValueError(f"No parameters to fit{f' in {where}' if where else ''}: give at least one, "
                         "e.g. eta_s,mu,C.")
    return checked_keys(resolve_name(written, where=where) for written in names)


def checked_keys(keys) -> tuple[str, ...]:
    """Registry keys, de-duplicated in order and checked: at most one of each group of
    `EXCLUSIVE`."""
    seen = tuple(dict.fromkeys(keys))
    for group, quantity in EXCLUSIVE:
        chosen = [name for name in group if name in seen]
        if len(chosen) > 1:
            raise ValueError(
                f"Parameters {' and '.join(map(public_label, chosen))} describe {quantity}; fit only one."
            )
    return tuple(seen)


@dataclasses.dataclass(frozen=True)
class ParameterInstance:
    """One free number of a fit: a spec bound to an experiment and/or channel.

    `label` is how reports name it: `eta`, `striker_velocity[run1]`, `gain[run1:wall]`.
    """

    spec: ParameterSpec
    experiment: int | None = None
    channel: str | None = None
    label: str = ""

    @property
    def name(self) -> str:
        return self.spec.name


def build_instances(names, experiments) -> list[ParameterInstance]:
    """The free numbers of a fit of `names` (checked registry names) on `experiments`.

    A global parameter is one number; an experiment-scoped one, one per file
    (`striker_velocity[run1]`); a channel-scoped one, one per channel of each file
    (`gain[run1:wall]`); a sensor-scoped one, one per channel name, shared by the files
    that record it (`sensor_gain[wall]`).
    """
    instances = []
    for name in names:
        spec = get_spec(name)
        if spec.scope == "global":
            instances.append(ParameterInstance(spec, label=name))
        elif spec.scope == "experiment":
            for e, experiment in enumerate(experiments):
                instances.append(ParameterInstance(spec, e, label=f"{name}[{experiment.label}]"))
        elif spec.scope == "channel":
            for e, experiment in enumerate(experiments):
                for channel in experiment.channels:
                    instances.append(
                        ParameterInstance(spec, e, channel, label=f"{name}[{experiment.label}:{channel}]")
                    )
        else:
            sensors = dict.fromkeys(c for experiment in experiments for c in experiment.channels)
            instances.extend(ParameterInstance(spec, None, c, label=f"{name}[{c}]") for c in sensors)
    return instances


def to_unbounded(instances, values) -> np.ndarray:
    """Physical values -> optimiser coordinates z (numpy)."""
    values = np.asarray(values, dtype=float)
    z = np.empty_like(values)
    for i, inst in enumerate(instances):
        _, centre, half, _ = inst.spec.transform_constants()
        value = values[i]
        if not inst.spec.in_bounds(value):
            raise ValueError(
                f"Start value of {inst.label} = {value:g} {inst.spec.unit} is outside its bounds "
                f"({inst.spec.lower:g}, {inst.spec.upper:g}); give a start inside them."
            )
        s = inst.spec.to_s(value)
        ratio = np.clip((s - centre) / half, -1 + 1e-12, 1 - 1e-12)
        z[i] = centre + half * np.arctanh(ratio)
    return z


def transform_arrays(instances) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(space code, centre, half, scale) arrays for `from_unbounded`."""
    constants = np.array([inst.spec.transform_constants() for inst in instances], dtype=float)
    if len(instances) == 0:
        constants = np.zeros((0, 4))
    return constants[:, 0], constants[:, 1], constants[:, 2], constants[:, 3]


def from_unbounded(constants, z):
    """Optimiser coordinates z -> physical values (jax, differentiable)."""
    space, centre, half, scale = constants
    s = centre + half * jnp.tanh((z - centre) / half)
    log_value = jnp.exp(jnp.where(space == 0, s, 0.0))
    asinh_value = scale * jnp.abs(jnp.sinh(jnp.where(space == 1, s, 0.0)))
    return jnp.where(space == 0, log_value, jnp.where(space == 1, asinh_value, s * scale))
