"""The library of candidate missing effects, and the forward model that can switch each on.

Every effect is an optional term of the chain model with one or more strength parameters
whose value 0 is the base model (the effect switched off). All of them act through one
forward model (`effects_forward_model`), so a diagnosis compiles the simulator once and
frees or holds strengths as it goes.

| identifier | parameter(s) (0 = off) | what it changes |
|---|---|---|
| `viscous_damping` | `eta_s` (s) | Kuwabara-Kono $F_v = \\eta\\kappa\\,\\partial_t\\delta^{3/2}$ added to $\\eta$ of the header |
| `dashpot_damping` | `dashpot_n_s_m` (N s/m) | a linear dashpot $\\gamma\\dot\\delta$ at every contact in compression, $F = \\kappa\\delta^{3/2} + \\gamma\\dot\\delta$ clipped at 0 (Herbold & Nesterenko, PRE 75, 021304, 2007; Carretero-Gonzalez et al., PRL 102, 024102, 2009): the competing law of `viscous_damping` |
| `track_friction` | `mu` | Coulomb friction $\\mu m g$ of the beads on the track |
| `rotational_friction` | `mu_star` | uniform stiffness scale $\\kappa^* = (1+\\mu^*)\\kappa$ of every contact; the paper's thwarted rotation, but equally an error in the beads' modulus: in this form the two cannot be told apart |
| `sensor_dynamics` | `sensor_beta`, `sensor_rate`, `sensor_coupling` | a `contact_K` channel is the signal of a sensor embedded in bead K (Eq. 4 of the paper): $\\ddot F_s + \\omega_0^2F_s = \\omega_0^2[(1-\\beta)F_K + \\beta F_{K-1}]$, with `sensor_rate` $= (f_{ref}/f_0)^2$, $f_{ref}$ = 100 kHz; `sensor_coupling` c scales how much the sensor's compression also shortens the bead: c = 1 the split-bead mechanics, c = 0 the paper's filter form (the chain unaffected) |
| `wall_compliance` | `wall_softening` | wall modulus $Y_w = Y_{w,0}e^{-w}$ (w > 0: softer than the header's) |
| `bead_dispersion` | `bead_radius_dev_1..N` | relative radius deviation of each bead at fixed density (mass $\\propto R^3$, stiffness follows) |
| `precompression` | `preload_n` (N), `preload_seen` | static preload added to the header's; `preload_seen` is the share of it the channels read (0: piezo sensors, which read changes of force only; 1: DC sensors); channels a file lists in `ac_channels` never read it |
| `contact_exponent` | `exponent_shift`, `exponent_stiffness` | every contact follows $F = (1+s)\\kappa\\,\\delta_r^{3/2}(\\delta/\\delta_r)^n$ with $n = 3/2 + $ `exponent_shift` (non-ideal, rough or non-spherical contacts; `hertzchain.contact.power_law_force`): the stiffness at the overlap $\\delta_r$ of a reference force near the data's is fitted with it (`exponent_stiffness` s), so that n and the stiffness stay apart and a law normalised elsewhere is still matched |
| `plasticity` | `yield_softening` | elastic-plastic contacts that match measured ones (`hertzchain.contact.jackson_green_contact`: Jackson & Green 2005 loading to a hardness of 2.84 $\\sigma_Y$, Hertzian unloading from the flattened contact) with yield stress $\\sigma_{Y,0}/y$, i.e. yield forces $F_{Y,0}/y^3$ ($\\sigma_{Y,0}$: the header's, else 2 GPa); y = 0 never yields, y = 1 leaves Hertz at 1.55 kN between the paper's beads |

`sensor_dynamics` has two parts, both exact for a bead cut in two around a sensor (the
core's split-bead model, `ChainSetup.sensor_beads`) and both regular at $f_0 = \\infty$ (the
base model), so derivatives exist at "off": the chain is simulated with each recorded
contact's bead (K >= 1) shortened by c times its sensor's compression
(`hertzchain.compliant_sensor`: the soft sensor delays and scatters the wave; c = 0 is the
paper's reading of Eq. 4 as a filter on a rigid bead's forces), and the
channel is the sensor force of Eq. 4 driven by that chain's contacts K-1 and K, from the
exact discretisation of Eq. 4 (`hertzchain.sensor.sensor_signal`) for $f_0$ below 2 MHz and
above it (sensor_rate < 0.0025) its first-order expansion $F_s = u - \\ddot u/\\omega_0^2$.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from hertzchain import laws
from hertzchain.chain import DEPRECATED_LAW_KEYWORDS, ChainSetup
from hertzchain.compliant_sensor import CompliantSensors
from hertzchain.integrate import Recording, solve
from hertzchain.sensor import sensor_signal
from hertzchain.units import format_measured

from .model import ForwardModel, KernelForm
from .parameters import REGISTRY, ParameterSpec, register_parameter

SENSOR_REFERENCE_HZ = 100e3
# Above this f0 the sensor filter uses its first-order expansion (sensor_rate below the switch).
_SENSOR_EXACT_BELOW_HZ = 2e6
_SENSOR_SWITCH_RATE = (SENSOR_REFERENCE_HZ / _SENSOR_EXACT_BELOW_HZ) ** 2
# Yield stress used by `plasticity` when the header's beads never yield (the paper's 2 GPa).
DEFAULT_YIELD_STRESS_PA = 2e9
# A rigid nominal wall is represented as this many times stiffer than the beads.
_RIGID_WALL_FACTOR = 1e3
PREFIX = "dx_"


@dataclasses.dataclass(frozen=True, kw_only=True)
class Effect:
    """A candidate missing effect.

    **Fields:** `name` (identifier), `parameters` (registry names of its strengths, in the
    forward model's `extras`), `summary` (the model term), `signature` (what it leaves in
    the data), `one_sided` (strengths that are physically >= 0, so a fit at the bound means
    "absent").
    """

    name: str
    parameters: tuple[str, ...]
    summary: str
    signature: str
    one_sided: bool = True


def _spec(name, unit, lower, upper, description):
    return ParameterSpec(PREFIX + name, unit, "global", "linear", lower, upper, kind="extra",
                         scale=1.0, default=0.0, description=description)


_SPECS = (
    _spec("eta_s", "s", 0.0 - 1e-30, 1e-3, "viscous_damping: added viscoelastic time eta (s)"),
    _spec("dashpot_n_s_m", "N s/m", 0.0 - 1e-30, 1e5, "dashpot_damping: linear dashpot at every contact (N s/m)"),
    _spec("mu", "", 0.0 - 1e-30, 3.0, "track_friction: friction coefficient on the track"),
    _spec("mu_star", "", -0.5, 1.0, "rotational_friction: uniform stiffness scale kappa* = (1+mu*) kappa"),
    _spec("sensor_beta", "", 0.0 - 1e-30, 0.5, "sensor_dynamics: mass fraction beta of the front half"),
    _spec("sensor_rate", "", 0.0 - 1e-30, 1e4, "sensor_dynamics: (100 kHz / f0)^2"),
    _spec("sensor_coupling", "", 0.0 - 1e-30, 1.0,
          "sensor_dynamics: share of the sensor's compression that shortens its bead (1: split bead, 0: filter)"),
    _spec("wall_softening", "", -5.0, 12.0, "wall_compliance: log(Y_w,header / Y_w)"),
    _spec("preload_n", "N", 0.0 - 1e-30, 1e4, "precompression: static preload (N)"),
    _spec("preload_seen", "", 0.0 - 1e-30, 1.0,
          "precompression: share of the static preload the channels read (0: AC/piezo, 1: DC)"),
    _spec("yield_softening", "", 0.0 - 1e-30, 20.0, "plasticity: sigma_Y,0 / sigma_Y"),
    _spec("exponent_shift", "", -0.5, 1.0, "contact_exponent: n - 3/2 of every contact's power law"),
    _spec("exponent_stiffness", "", -0.5, 1.0, "contact_exponent: relative stiffness at the reference overlap"),
)
for _s in _SPECS:
    if _s.name not in REGISTRY:
        register_parameter(_s)


def dispersion_parameter(bead: int) -> str:
    """Registry name of the radius deviation of bead `bead` (1..N), registered on demand."""
    name = f"{PREFIX}bead_radius_dev_{bead}"
    if name not in REGISTRY:
        register_parameter(_spec(f"bead_radius_dev_{bead}", "", -0.2, 0.2,
                                 f"bead_dispersion: relative radius deviation of bead {bead}"))
    return name


def library(n_beads: int) -> dict[str, Effect]:
    """The candidate effects for a chain of `n_beads`, by identifier, in a fixed order."""
    p = PREFIX
    effects = (
        Effect(
            name="viscous_damping",
            parameters=(p + "eta_s",),
            summary="F_v = eta kappa d(delta^3/2)/dt (Kuwabara-Kono)",
            signature=("peaks lower and pulses broader, increasingly along the chain, most at "
                       "high amplitude; a slow trailing tail"),
        ),
        Effect(
            name="dashpot_damping",
            parameters=(p + "dashpot_n_s_m",),
            summary="F_v = gamma d(delta)/dt, a linear dashpot",
            signature=("peaks lower along the chain with a loss that does not vanish at contact "
                       "onset: relatively larger at low amplitude than viscous_damping's"),
        ),
        Effect(
            name="track_friction",
            parameters=(p + "mu",),
            summary="Coulomb friction mu m g of every bead on the track",
            signature=("amplitude loss mostly at low amplitude (relative loss ~ 1/F_m); beads "
                       "behind the pulse stop"),
        ),
        Effect(
            name="rotational_friction",
            parameters=(p + "mu_star",),
            summary=("uniform contact-stiffness scale kappa* = (1+mu*) kappa (thwarted rotation, "
                     "or equally an error in the beads' Young's modulus: not separable in this "
                     "form)"),
            signature=("phase misfit only: pulses earlier (mu* > 0) by ~mu*/3 of the travel time, "
                       "at all amplitudes"),
            one_sided=False,
        ),
        Effect(
            name="sensor_dynamics",
            parameters=(p + "sensor_beta", p + "sensor_rate", p + "sensor_coupling"),
            summary=("contact channels are embedded-sensor signals (Eq. 4, unknown beta and f0; "
                     "split-bead mechanics or the filter form, by the coupling c)"),
            signature=("odd (derivative-shaped) residual in contact channels only, high-frequency "
                       "ringing; the wall channel is untouched"),
        ),
        Effect(
            name="wall_compliance",
            parameters=(p + "wall_softening",),
            summary="wall Young's modulus differs from the header's",
            signature=("wall peak lower and longer (softer wall), later reflected pulse; nothing "
                       "before the wall"),
            one_sided=False,
        ),
        Effect(
            name="bead_dispersion",
            parameters=tuple(dispersion_parameter(b) for b in range(1, n_beads + 1)),
            summary="bead radii (and masses, at fixed density) vary along the chain",
            signature=("position-specific pattern of amplitude and arrival residuals, same at "
                       "every amplitude"),
            one_sided=False,
        ),
        Effect(
            name="precompression",
            parameters=(p + "preload_n", p + "preload_seen"),
            summary="static preload F0 on the chain, read by DC sensors or not by AC (piezo) ones",
            signature=("faster, wider pulses at low amplitude; a baseline offset only on "
                       "DC-coupled channels"),
        ),
        Effect(
            name="contact_exponent",
            parameters=(p + "exponent_shift", p + "exponent_stiffness"),
            summary=("F = kappa_n delta^n at every contact, n and the stiffness at a reference "
                     "overlap free"),
            signature=("pulses narrower or wider than Hertz's and a speed that scales with "
                       "amplitude other than F^(1/6): (n - 1)/(2n) instead"),
            one_sided=False,
        ),
        Effect(
            name="plasticity",
            parameters=(p + "yield_softening",),
            summary="elastic-plastic contacts (Jackson & Green 2005 loading, hardness 2.84 sigma_Y)",
            signature=("flattened peaks and extra loss only above the yield force (a threshold in "
                       "amplitude)"),
        ),
    )
    return {effect.name: effect for effect in effects}


EFFECT_NAMES = tuple(library(1))

# Fitted setup parameters (fitting.parameters) that already stand for an effect: freeing one
# of them makes that effect's candidate redundant.
COVERED_BY = {
    "eta": "viscous_damping", "mu": "track_friction", "C": "rotational_friction",
    "mu_star": "rotational_friction", "wall_youngs": "wall_compliance",
    "precompression": "precompression",
}


def rebuild_setup(setup: ChainSetup, **changes) -> ChainSetup:
    """A copy of `setup` with fields replaced, static ones (`contact_law`'s type, `sensor_beads`)
    included; `eta_s` and `dashpot_n_s_m` replace the coefficients of those laws.

    Works on traced setups (inside `jit`/`vmap`/`jacfwd`): the constructor's concrete checks
    skip traced values.
    """
    values = {f.name: getattr(setup, f.name) for f in dataclasses.fields(setup)}
    if any(name in changes for name in DEPRECATED_LAW_KEYWORDS):  # the former spelling of contact_law
        del values["contact_law"]
    values.update(changes)
    return ChainSetup(setup.n_beads, **values)


def _second_difference(series, step_s):
    inner = (series[2:] - 2.0 * series[1:-1] + series[:-2]) / step_s**2
    return jnp.concatenate([inner[:1], inner, inner[-1:]])


def sensor_output(front_n, back_n, beta, rate, step_s):
    """Embedded-sensor signal of Eq. 4 from the forces on its front and back halves, N.

    `front_n`, `back_n`: (n,) forces at contact K and K-1 on an even grid of `step_s`;
    `rate` $= (f_{ref}/f_0)^2$. Differentiable in `beta` and `rate`, also at `rate = 0`.
    """
    drive = (1.0 - beta) * front_n + beta * back_n
    omega_ref = 2.0 * math.pi * SENSOR_REFERENCE_HZ
    series_first = drive - rate / omega_ref**2 * _second_difference(drive, step_s)
    exact = rate > _SENSOR_SWITCH_RATE
    safe_rate = jnp.where(exact, rate, 1.0)
    f0 = SENSOR_REFERENCE_HZ / jnp.sqrt(safe_rate)
    time = step_s * jnp.arange(front_n.shape[0], dtype=jnp.float64)
    filtered = sensor_signal(time, front_n, back_n, beta=beta, f0_hz=f0)
    return jnp.where(exact, filtered, series_first)


# apply_effects is not a set of `hertzchain.parameters` setters (the registry `fitting.parameters`
# uses): those write the absolute value of a named quantity, while an effect strength is a
# departure from the header's chain whose 0 is the base model (added to its eta, mu, dashpot
# and preload, composed with its mu*, scaling its wall modulus and yield stress), several act
# on what no registry name covers (each bead's radius at fixed density, the contact exponent at
# a reference overlap) or switch the contact law (`plastic`, `power_law`: static fields, a new
# setup), and `sensor_*` and `preload_seen` act on the sensors and the channels, not on the
# setup. Their names, units and bounds are registered once, in `fitting.parameters` (kind
# "extra", `_SPECS`); what they do to a chain is defined here only.
def apply_effects(setup: ChainSetup, extras: dict, *, plastic: bool = True,
                  power_law: bool = False) -> ChainSetup:
    """The setup with every effect strength of `extras` applied.

    `plastic`: elastic-plastic contacts, `laws.JacksonGreen` (needed as soon as `yield_softening` > 0);
    `False` gives Hertz contacts, the same model where `yield_softening` is 0 (an infinite
    yield force) at a fraction of the cost. `power_law`: power-law contacts of exponent
    3/2 + `exponent_shift`, equal to Hertz at the overlap of `extras["reference_force_n"]`
    (needed as soon as `exponent_shift` is not 0; not with `plastic`).
    """
    p = PREFIX
    n = setup.n_beads
    deviations = jnp.stack([jnp.asarray(extras.get(f"{p}bead_radius_dev_{b}", 0.0), dtype=jnp.float64)
                            for b in range(1, n + 1)])
    radius = setup.bead_radius_m * (1.0 + deviations)
    wall = _nominal_wall_youngs(setup) * jnp.exp(-extras[p + "wall_softening"])
    sigma0 = nominal_yield_stress_pa(setup)
    softening = extras[p + "yield_softening"]
    yields = softening > 0
    sigma = jnp.where(yields, sigma0 / jnp.where(yields, softening, 1.0), jnp.inf)
    if plastic and power_law:
        raise ValueError("apply_effects: plastic and power_law contacts cannot be combined: the elastic-plastic "
                         "law is built on Hertz contacts.")
    if plastic:
        contact_law = laws.JacksonGreen()
    elif power_law:
        reference = (extras["reference_force_n"] / setup.contact_kappa()[min(1, n - 1)]) ** (2 / 3)
        contact_law = laws.PowerLaw(1.5 + extras[p + "exponent_shift"], reference)
    else:
        contact_law = laws.Hertz()
    return rebuild_setup(
        setup,
        bead_radius_m=radius,
        eta_s=setup.eta_s + extras[p + "eta_s"],
        dashpot_n_s_m=setup.dashpot_n_s_m + extras[p + "dashpot_n_s_m"],
        mu=setup.mu + extras[p + "mu"],
        mu_star=(1.0 + setup.mu_star) * (1.0 + extras[p + "mu_star"]) * (1.0 + extras[p + "exponent_stiffness"])
        - 1.0,
        wall_youngs_pa=wall,
        precompression_n=setup.precompression_n + extras[p + "preload_n"],
        bead_yield_stress_pa=sigma,
        contact_law=contact_law,
    )


class _Forces(eqx.Module):
    """The part of `hertzchain.Traces` a fit reads: `forces_n`, and `rest_n`, what the
    channels read with the chain at rest before the impact (N)."""

    forces_n: dict
    rest_n: jax.Array


@dataclasses.dataclass(frozen=True)
class EffectsSimulation(KernelForm):
    """The chain with every effect of `extras` switched on: `apply_effects`, the recorded
    contacts and what the channels read (`readings`: the unseen preload, the sensors' Eq. 4).

    Called, it simulates with `hertzchain.solve` (one chain; a fit takes it under `vmap`).
    As a `fitting.model.KernelForm` the batched kernel runs it (the same numbers to
    round-off). `compliant` (default) shortens each recorded bead by `sensor_coupling` times
    its sensor's compression (`compliant_sensors`), which the C++ kernel runs on the CPU (its
    sensor libraries, one per contact law: blocks of 4 chains, with the sensors' arithmetic in
    every step) and the JAX kernel elsewhere; off, `sensor_coupling` acts on nothing: exact
    wherever the compliance,
    `sensor_coupling` x `sensor_rate`, is 0 (the base model), and so are its derivatives in
    those two where the other of them is 0. `dashpot` off: `dashpot_n_s_m` acts on nothing
    (exact where it is 0, not its derivative), so that the kernel is built without the
    dashpot's term (which costs every run that carries it). These twins run on the C++
    kernel; `fitting.diagnosis` chooses where they hold.
    """

    plastic: bool
    power_law: bool = False
    compliant: bool = True
    dashpot: bool = True

    def setup(self, setup, extras):
        if not self.dashpot:
            extras = dict(extras, **{PREFIX + "dashpot_n_s_m": 0.0})
        return apply_effects(setup, extras, plastic=self.plastic, power_law=self.power_law)

    def physics(self, names):
        """The kernel physics `extras` named `names` can switch on."""
        switches = {PREFIX + "eta_s": "viscous", PREFIX + "mu": "friction", PREFIX + "preload_n": "preload"}
        if self.dashpot:
            switches[PREFIX + "dashpot_n_s_m"] = "dashpot"
        return {switches[name] for name in names if name in switches}

    def recording(self, recording):
        """`recording` with the back contact (K-1) of every recorded contact K's sensor."""
        behind = {k - 1 for k in recording.contacts if k >= 1}
        return Recording(contacts=tuple(sorted(set(recording.contacts) | behind)))

    def readings(self, forces_n, setup, extras, grid, recording):
        """What the channels of `recording` read from the simulated forces `forces_n` (name ->
        (S,), N) of the chain `setup` (the effects applied): the unseen share of the preload
        taken off, each contact K through its sensor's Eq. 4; and what they read at rest."""
        p = PREFIX
        unseen = (1.0 - extras[p + "preload_seen"]) * extras[p + "preload_n"]
        forces = {name: value - unseen for name, value in forces_n.items()}
        start = setup.precompression_n - unseen
        step = grid.sample_interval_s
        for k in recording.contacts:
            front = jnp.concatenate([start[None], forces[f"contact_{k}"]])
            back = front if k == 0 else jnp.concatenate([start[None], forces[f"contact_{k - 1}"]])
            signal = sensor_output(front, back, extras[p + "sensor_beta"], extras[p + "sensor_rate"], step)
            forces[f"contact_{k}"] = signal[1:]
        return forces, start

    def compliant_sensors(self, recording, extras):
        """The sensor of every recorded contact K >= 1 in its bead K, shortened by
        `sensor_coupling` x `sensor_rate` / (2 pi `SENSOR_REFERENCE_HZ`)^2 per unit of force
        (None without `compliant_sensors`, or without such a contact)."""
        beads = tuple(k for k in recording.contacts if k >= 1)
        if not (beads and self.compliant):
            return None
        p = PREFIX
        omega_ref = 2.0 * math.pi * SENSOR_REFERENCE_HZ
        return CompliantSensors(beads, extras[p + "sensor_beta"],
                                extras[p + "sensor_coupling"] * extras[p + "sensor_rate"] / omega_ref**2)

    def __call__(self, setup, grid, recording, extras):
        changed = self.setup(setup, extras)
        traces = solve(changed, grid, self.recording(recording),
                       compliant_sensors=self.compliant_sensors(recording, extras))
        forces, rest = self.readings(traces.forces_n, changed, extras, grid, recording)
        return _Forces(forces_n=forces, rest_n=rest)


def effects_forward_model(n_beads: int, steps_per_contact: int = 200, *, plastic: bool = True,
                          power_law: bool = False, reference_force_n: float = 100.0,
                          compliant_sensors: bool = True, dashpot: bool = True) -> ForwardModel:
    """A `ForwardModel` with every effect of `library(n_beads)` available, all off by default.

    Effect strengths are fitted parameters of kind "extra" (registry names starting with
    `dx_`); the ones not fitted take their default 0 (off). `plastic=False`: Hertz contacts
    whatever `yield_softening` (exact where it is 0, several times faster); `power_law`:
    power-law contacts (for `exponent_shift` other than 0), equal to Hertz's at the overlap
    of `reference_force_n` (N; choose it near the data's forces). Either way the batched
    kernel runs it: `compliant_sensors=False` (rigid sensor beads) and `dashpot=False`
    (without the `dashpot_damping` effect) give the models its C++ kernel runs
    (`EffectsSimulation`).
    """
    if plastic and power_law:
        raise ValueError("effects_forward_model: plastic and power_law contacts cannot be combined.")
    defaults = {spec.name: 0.0 for spec in _SPECS}
    for b in range(1, n_beads + 1):
        defaults[dispersion_parameter(b)] = 0.0
    defaults["reference_force_n"] = float(reference_force_n)
    simulation = EffectsSimulation(plastic=plastic, power_law=power_law, compliant=compliant_sensors,
                                   dashpot=dashpot)
    return ForwardModel(simulate=simulation, steps_per_contact=steps_per_contact, extras_defaults=defaults,
                        kernel=simulation)


def nominal_yield_stress_pa(setup: ChainSetup) -> jax.Array:
    """sigma_Y,0, the beads' yield stress at yield_softening 1, Pa: the header's, else
    `DEFAULT_YIELD_STRESS_PA` where the header's beads never yield (traceable)."""
    stress = setup.bead_yield_stress_pa
    return jnp.where(jnp.isfinite(stress), stress, DEFAULT_YIELD_STRESS_PA)


def nominal_yield_forces_n(setup: ChainSetup) -> np.ndarray:
    """Every contact's yield force under `plasticity` at yield_softening 1, N: striker-bead,
    bead-bead..., wall (`nominal_yield_stress_pa`)."""
    nominal = rebuild_setup(setup, contact_law=laws.JacksonGreen(),
                            bead_yield_stress_pa=float(nominal_yield_stress_pa(setup)))
    return np.asarray(nominal.contact_yield_force_n(), dtype=float)


def _nominal_wall_youngs(setup: ChainSetup) -> jax.Array:
    """`nominal_wall_youngs_pa`, traceable."""
    wall = setup.wall_youngs_pa
    return jnp.where(jnp.isfinite(wall), wall, _RIGID_WALL_FACTOR * setup.bead_youngs_pa[-1])


def nominal_wall_youngs_pa(setup: ChainSetup) -> float:
    """The wall's Young's modulus at wall_softening 0, Pa: the header's, a rigid wall's stand-in
    (`_RIGID_WALL_FACTOR` times the last bead's) where the header has none."""
    return float(_nominal_wall_youngs(setup))


def fitted_wall_youngs_pa(setup: ChainSetup, softening: float) -> float:
    """The wall's Young's modulus, Pa, that `wall_softening` = `softening` gives the model of
    `setup`: Y_w = Y_w,nominal e^-w (`nominal_wall_youngs_pa`)."""
    return nominal_wall_youngs_pa(setup) * math.exp(-softening)


def describe_wall(setup: ChainSetup, softening: float, softening_stderr: float) -> str:
    """The fitted `wall_softening` in words: the wall's Young's modulus (GPa) with its standard
    error (Y_w = Y_w,header e^-w, so sigma_Y = Y_w sigma_w), against the header's."""
    nominal = nominal_wall_youngs_pa(setup)
    wall = fitted_wall_youngs_pa(setup, softening)
    header = (f"header {nominal / 1e9:.4g} GPa" if math.isfinite(float(setup.wall_youngs_pa))
              else "header: rigid")
    return (f" wall_compliance: wall Young's modulus {format_measured(wall, wall * softening_stderr, 'Pa')} "
            f"({header}).")


def describe_plasticity(setup: ChainSetup, softening: float, softening_stderr: float) -> str:
    """The fitted `yield_softening` in words: the yield stress (MPa) with its standard error,
    and the force at which contacts between beads then leave Hertz (N)."""
    sigma0 = float(nominal_yield_stress_pa(setup))
    fitted = sigma0 / softening
    error = sigma0 * softening_stderr / softening**2
    forces = nominal_yield_forces_n(setup) / softening**3
    force = forces[1 if forces.size > 2 else 0]  # the first bead-bead contact
    return (f" plasticity: yield stress {fitted / 1e6:.4g} +- {error / 1e6:.2g} MPa (contacts: Jackson & Green "
            f"2005 loading to 2.84 sigma_Y); contacts between beads leave Hertz from {force:.4g} N, the wall "
            f"contact from {forces[-1]:.4g} N.")
