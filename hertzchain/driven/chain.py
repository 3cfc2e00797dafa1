"""A precompressed chain of beads between a driven face and a fixed wall.

    driver (prescribed displacement u(t)) | bead 1 | bead 2 | ... | bead n | wall (fixed)
                                      contact 0  contact 1   ...  contact n-1  contact n

Contact 0 joins the driver face to bead 1, contact K joins bead K to bead K + 1, contact n
joins bead n to the wall; each has its own Hertz stiffness $\\kappa_k$ (N/m^{3/2}), and all
follow one contact law (`hertzchain.laws`, `Hertz` by default). Contact k carries the static
force $F_k$ (N) at rest, at the overlap $\\delta_k^0$ the law gives for it
(`overlap_at_force`; Hertz: $(F_k/\\kappa_k)^{2/3}$). Displacements $x_i$ are measured from
that equilibrium (positive towards the wall), so the overlaps are

$\\delta_0 = \\delta_0^0 + u - x_1$, $\\delta_k = \\delta_k^0 + x_k - x_{k+1}$,
$\\delta_n = \\delta_n^0 + x_n$,

and bead $i$ obeys $m_i\\ddot x_i = F_{i-1} - F_i + S_i - m_i\\gamma_i\\dot x_i$, with the
contact forces of the contact law plus the dissipation laws (`Viscoelastic`, Kuwabara-Kono
damping of coefficient `eta_s`, by default), clipped at zero (the beads can separate), and
a viscous drag $-m\\gamma v$ on each bead (the driver and the wall are the frame at rest).

Preload per contact: without gravity or support forces a bead is in equilibrium only if its
two contacts carry the same force, so one `precompression_n` for all is the physical case.
Unequal static forces (an (n + 1,) `precompression_n`) mean the beads' supports hold each
bead with the constant force $S_i = F_i - F_{i-1}$ (N, towards the wall positive): friction
at the supports that locked the beads in while the stack was pressed, or gravity along an
inclined chain. That force is part of the model (`support_force_n`): it keeps the stated
static state an equilibrium and does not change during the motion.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import contact, laws
from ..materials import sphere_mass_kg
from ..precision import require_float64
from ..validation import check_positive_parameters, is_concrete
from .drive import DRIVE_STROKES, ActuatorMode, RayleighStroke


class DrivenChain(eqx.Module):
    """The physical constants of a driven, precompressed chain of n beads (all traceable).

    **Fields:**

    - `bead_mass_kg`: (n,) bead masses, kg.
    - `contact_kappa_n_m1p5`: (n + 1,) Hertz stiffness of each contact, N/m^{3/2}:
      contact 0 = driver face-bead 1, contact K = bead K-bead K+1, contact n = bead n-wall.
    - `precompression_n`: () static force $F_0$ every contact carries at rest, or (n + 1,)
      one per contact (then the supports hold the beads, see the module docstring), N (> 0).
    - `damping_rate_per_s`: (n,) viscous damping rate $\\gamma$ of each bead, 1/s (force
      $-m\\gamma v$; a lone bead's damping ratio is $\\gamma / (2\\omega_0)$).
    - `contact_law`: the elastic law of every contact (`hertzchain.laws.AbstractContactLaw`;
      default `laws.Hertz()`). A law's array parameters are one value for all contacts or
      an (n + 1,) array, one per contact.
    - `dissipation`: tuple of rate-dependent contact laws (`laws.AbstractDissipation`;
      default `(laws.Viscoelastic(eta_s),)`), parameters likewise scalar or (n + 1,).
    - `contact_yield_force_n`, `contact_reduced_radius_m`, `contact_poisson`: (n + 1,) or
      None, and `yield_stress_pa`: () or None: what the elastic-plastic laws read
      (`laws.Thornton`: the yield force, N; `laws.JacksonGreen`: reduced radius, m, Poisson
      ratio and yield stress, Pa); `from_materials` fills them from `bead_yield_stress_pa`.
    - `support_friction`: micro-slip friction at every bead's supports
      (`laws.IwanSupport`, parameters scalar or (n,)), or None (default: no support force
      but the static one of unequal preloads).
    - `drive_stroke`: the driver's stroke law (`drive.RayleighStroke`: growing with amplitude;
      `drive.ActuatorMode`: through one mode of the actuator), or None (default: the face
      moves by the nominal amplitude, $a\\cos\\theta$).

    `eta_s` (s) is the shorthand of the `Viscoelastic` law's coefficient (a keyword of the
    constructor and a read-only property). Build one from material constants with
    `DrivenChain.from_materials`, or directly from arrays; `eqx.tree_at` replaces a field
    (e.g. for a fit). Every array is a float64 leaf, so `jax.jacfwd` and `jax.vmap` go
    through it.
    """

    bead_mass_kg: jax.Array
    contact_kappa_n_m1p5: jax.Array
    precompression_n: jax.Array
    damping_rate_per_s: jax.Array
    contact_law: laws.AbstractContactLaw
    dissipation: tuple[laws.AbstractDissipation, ...]
    contact_yield_force_n: jax.Array | None
    contact_reduced_radius_m: jax.Array | None
    contact_poisson: jax.Array | None
    yield_stress_pa: jax.Array | None
    support_friction: laws.IwanSupport | None
    drive_stroke: RayleighStroke | ActuatorMode | None

    def __init__(self, bead_mass_kg, contact_kappa_n_m1p5, precompression_n, damping_rate_per_s, eta_s=None, *,
                 contact_law: laws.AbstractContactLaw | None = None, dissipation=None, contact_yield_force_n=None,
                 contact_reduced_radius_m=None, contact_poisson=None, yield_stress_pa=None, support_friction=None,
                 drive_stroke: RayleighStroke | ActuatorMode | None = None):
        require_float64("DrivenChain")
        self.bead_mass_kg = jnp.atleast_1d(jnp.asarray(bead_mass_kg, dtype=jnp.float64))
        n = self.bead_mass_kg.shape[0]
        self.contact_kappa_n_m1p5 = jnp.asarray(contact_kappa_n_m1p5, dtype=jnp.float64)
        self.precompression_n = jnp.asarray(precompression_n, dtype=jnp.float64)
        self.damping_rate_per_s = jnp.broadcast_to(jnp.asarray(damping_rate_per_s, dtype=jnp.float64), (n,))
        self.contact_law = laws.Hertz() if contact_law is None else contact_law
        self.dissipation = _dissipation(dissipation, eta_s)
        self.support_friction = support_friction
        self.drive_stroke = drive_stroke
        optional = {"contact_yield_force_n": contact_yield_force_n, "contact_reduced_radius_m": contact_reduced_radius_m,
                    "contact_poisson": contact_poisson, "yield_stress_pa": yield_stress_pa}
        for name, value in optional.items():
            setattr(self, name, None if value is None else jnp.asarray(value, dtype=jnp.float64))
        _check_fields(self)

    @property
    def eta_s(self) -> jax.Array:
        """Kuwabara-Kono damping time of the contacts' `laws.Viscoelastic`, s (0 without one)."""
        for law in self.dissipation:
            if isinstance(law, laws.Viscoelastic):
                return law.eta_s
        return jnp.zeros(())

    def contact_constants(self) -> laws.ContactConstants:
        """What the chain gives its n + 1 contacts' law (`laws.ContactConstants`): the Hertz
        stiffness and, where set, the yield force, reduced radius, Poisson ratio and yield
        stress."""
        return laws.ContactConstants(self.contact_kappa_n_m1p5, self.contact_yield_force_n,
                                     self.contact_reduced_radius_m, self.contact_poisson, self.yield_stress_pa)

    def static_force_n(self) -> jax.Array:
        """(n + 1,) static force of every contact at rest, N."""
        return jnp.broadcast_to(self.precompression_n, self.contact_kappa_n_m1p5.shape)

    def support_force_n(self) -> jax.Array:
        """(n,) constant force the supports exert on every bead, $S_i = F_i - F_{i-1}$, N
        (positive towards the wall): zero for one precompression of all contacts."""
        force = self.static_force_n()
        return force[1:] - force[:-1]

    @property
    def runs_on_fused_kernel(self) -> bool:
        """Whether the fused host kernel (`hertzchain.driven.fused`) has this chain's physics:
        Hertz contacts, at most Kuwabara-Kono damping, one precompression of all contacts,
        no support friction, the nominal stroke.
        Other chains run the JAX kernel (the results say which ran)."""
        return (type(self.contact_law) is laws.Hertz and self.precompression_n.ndim == 0
                and self.support_friction is None and self.drive_stroke is None
                and all(type(law) is laws.Viscoelastic and jnp.ndim(law.eta_s) == 0 for law in self.dissipation)
                and len(self.dissipation) <= 1)

    @property
    def n_beads(self) -> int:
        """Number of beads n."""
        return self.bead_mass_kg.shape[0]

    @classmethod
    def from_materials(cls, *, n_beads: int, bead_radius_m: float, bead_youngs_pa: float, bead_poisson: float,
                       driver_youngs_pa: float, driver_poisson: float, wall_youngs_pa: float, wall_poisson: float,
                       precompression_n: float, damping_rate_per_s: float = 0.0, bead_mass_kg: float | None = None,
                       bead_density_kg_m3: float | None = None, eta_s: float | None = None,
                       contact_law: laws.AbstractContactLaw | None = None, dissipation=None,
                       bead_yield_stress_pa: float | None = None) -> DrivenChain:
        """n identical spheres of radius `bead_radius_m` between a flat driver face and a flat
        wall: Hertz sphere-flat stiffness (`contact.kappa_sphere_flat`) at the driver and the
        wall, sphere-sphere (`contact.kappa_sphere_sphere`) between beads. Give the bead mass
        either directly (`bead_mass_kg`) or through `bead_density_kg_m3` (a full sphere).
        Moduli in Pa (`inf` for a rigid face), Poisson ratios dimensionless, force in N
        (scalar or one per contact), damping rate in 1/s (the same for every bead), `eta_s`
        in s; `contact_law` and `dissipation` as the constructor's. `bead_yield_stress_pa`
        (Pa) gives the elastic-plastic laws their constants: the paper's mean-pressure yield
        force of every contact (`contact.yield_force`), the reduced radii and the beads'
        Poisson ratio."""
        constants = _material_constants(n_beads, bead_radius_m, bead_youngs_pa, bead_poisson, driver_youngs_pa,
                                        driver_poisson, wall_youngs_pa, wall_poisson, bead_mass_kg, bead_density_kg_m3,
                                        bead_yield_stress_pa)
        return cls(precompression_n=precompression_n,
                   damping_rate_per_s=jnp.full((int(n_beads),), damping_rate_per_s, dtype=jnp.float64),
                   eta_s=eta_s, contact_law=contact_law, dissipation=dissipation, **constants)

    def for_kernel(self) -> DrivenChain:
        """This chain as the compiled runs take it: the dissipation laws whose coefficient is
        a concrete 0 left out, so that the kernel leaves their terms out (the same numbers,
        about 1.5× faster for Kuwabara-Kono). A traced coefficient (e.g. one being fitted)
        stays."""
        kept = tuple(law for law in self.dissipation if not _concretely_inactive(law))
        if len(kept) == len(self.dissipation):
            return self
        return eqx.tree_at(lambda c: c.dissipation, self, kept)

    def static_overlap_m(self) -> jax.Array:
        """(n + 1,) overlap of every contact at rest, the contact law's `overlap_at_force` of
        its static force (Hertz: $(F_k/\\kappa_k)^{2/3}$), m."""
        return self.contact_law.overlap_at_force(self.static_force_n(), self.contact_constants())

    def contact_stiffness_n_m(self) -> jax.Array:
        """(n + 1,) linear stiffness of every contact about the static state, the contact
        law's `stiffness_at_force` (Hertz: $dF/d\\delta = \\tfrac32\\kappa^{2/3}F_0^{1/3}$), N/m."""
        return self.contact_law.stiffness_at_force(self.static_force_n(), self.contact_constants())

    def support_stiffness_n_m(self) -> jax.Array:
        """(n,) linear stiffness of every bead's supports about the static state, N/m: the
        micro-slip supports' stiffness before anything slips (`laws.IwanSupport`'s K; every
        slider sticks under an infinitesimal motion), zeros without support friction."""
        # operators only: the same code on NumPy leaves (`highest_frequency_bound_hz`)
        if self.support_friction is None:
            return 0.0 * self.bead_mass_kg
        return self.support_friction.stiffness_n_m + 0.0 * self.bead_mass_kg

    def describe(self) -> dict:
        """The chain as JSON-ready numbers (a sweep folder's manifest): the arrays, `eta_s`
        and, where they are not the defaults, the laws (type name and parameters) and the
        yield constants."""
        return _describe_chain(self)

    def highest_frequency_bound_hz(self) -> jax.Array:
        """An upper bound on the chain's highest linear mode frequency about the static state,
        Hz (Gershgorin's bound on $M^{-1}K$: $\\omega^2 \\le \\max_i (2(k_{i-1} + k_i) + k_{s,i})/m_i$,
        $k_s$ the supports' stiffness)."""
        k = self.contact_stiffness_n_m()
        # operators and methods only: the same code on NumPy leaves (checks of concrete inputs)
        return ((2.0 * (k[:-1] + k[1:]) + self.support_stiffness_n_m()) / self.bead_mass_kg).max() ** 0.5 / (2.0 * np.pi)


def _check_fields(chain: DrivenChain) -> None:
    """ValueError naming the field for a chain that cannot be run (shapes, signs, the laws'
    parameters and constants)."""
    n = chain.bead_mass_kg.shape[0]
    if chain.bead_mass_kg.ndim != 1 or n < 1:
        raise ValueError(f"bead_mass_kg: expected an (n,) array of bead masses in kg, got shape "
                         f"{chain.bead_mass_kg.shape}.")
    if chain.contact_kappa_n_m1p5.shape != (n + 1,):
        raise ValueError(
            f"contact_kappa_n_m1p5: expected {n + 1} stiffnesses (driver, {n - 1} between beads, "
            f"wall) for {n} beads, got shape {chain.contact_kappa_n_m1p5.shape}."
        )
    if chain.precompression_n.shape not in ((), (n + 1,)):
        raise ValueError(f"precompression_n: expected one static force in N, or one per contact ({n + 1}), got "
                         f"shape {chain.precompression_n.shape}.")
    if not isinstance(chain.contact_law, laws.AbstractContactLaw):
        raise ValueError(f"contact_law: expected a hertzchain.laws contact law (e.g. laws.Hertz(), "  # noqa: TRY004 (bad input is a ValueError here)
                         f"laws.PowerLaw(1.6)), got {chain.contact_law!r}.")
    for name in ("contact_yield_force_n", "contact_reduced_radius_m", "contact_poisson"):
        value = getattr(chain, name)
        if value is not None and value.shape not in ((), (n + 1,)):
            raise ValueError(f"{name}: expected one value per contact ({n + 1}), got shape {value.shape}.")
    _check_law_parameters((chain.contact_law, *chain.dissipation), n + 1)
    if chain.support_friction is not None:
        if not isinstance(chain.support_friction, laws.IwanSupport):
            raise ValueError(f"support_friction: expected a hertzchain.laws.IwanSupport, got {chain.support_friction!r}.")
        _check_law_parameters((chain.support_friction,), n)
    if chain.drive_stroke is not None and not isinstance(chain.drive_stroke, DRIVE_STROKES):
        raise ValueError(f"drive_stroke: expected a hertzchain.driven.RayleighStroke or ActuatorMode, "
                         f"got {chain.drive_stroke!r}.")
    check_positive_parameters("DrivenChain", (("bead_mass_kg", chain.bead_mass_kg, "kg"),
                                              ("contact_kappa_n_m1p5", chain.contact_kappa_n_m1p5, "N/m^1.5"),
                                              ("precompression_n", chain.precompression_n, "N")))
    check_positive_parameters("DrivenChain", (("damping_rate_per_s", chain.damping_rate_per_s, "1/s"),), zero_ok=True)
    _check_law_constants(chain)


def _material_constants(n_beads, radius_m, bead_youngs_pa, bead_poisson, driver_youngs_pa, driver_poisson,
                        wall_youngs_pa, wall_poisson, bead_mass_kg, bead_density_kg_m3, bead_yield_stress_pa) -> dict:
    """`from_materials`' masses and contact constants of `n_beads` identical spheres of radius
    `radius_m` (m) between a flat driver face and a flat wall: the bead masses (kg, given or
    full spheres of density `bead_density_kg_m3`, kg/m^3), the Hertz stiffness of every
    contact (N/m^{3/2}) and, with a yield stress (Pa; None: none), the constants of the
    elastic-plastic laws (`_yield_constants`)."""
    if (bead_mass_kg is None) == (bead_density_kg_m3 is None):
        raise ValueError("from_materials: give exactly one of bead_mass_kg (kg) or bead_density_kg_m3 (kg/m^3).")
    if int(n_beads) != n_beads or n_beads < 1:
        raise ValueError(f"n_beads: expected a positive whole number of beads, got {n_beads}.")
    radius = jnp.asarray(radius_m, dtype=jnp.float64)
    if bead_mass_kg is None:
        bead_mass_kg = sphere_mass_kg(radius, bead_density_kg_m3)
    driver = contact.kappa_sphere_flat(radius, bead_youngs_pa, bead_poisson, driver_youngs_pa, driver_poisson)
    wall = contact.kappa_sphere_flat(radius, bead_youngs_pa, bead_poisson, wall_youngs_pa, wall_poisson)
    between = contact.kappa_sphere_sphere(radius, bead_youngs_pa, bead_poisson, radius, bead_youngs_pa,
                                          bead_poisson)
    n = int(n_beads)
    kappa = jnp.concatenate([jnp.atleast_1d(driver), jnp.full((n - 1,), between), jnp.atleast_1d(wall)])
    plastic = {} if bead_yield_stress_pa is None else _yield_constants(
        n, radius, bead_youngs_pa, bead_poisson, driver_youngs_pa, driver_poisson, wall_youngs_pa, wall_poisson,
        bead_yield_stress_pa)
    return {"bead_mass_kg": jnp.full((n,), bead_mass_kg, dtype=jnp.float64), "contact_kappa_n_m1p5": kappa, **plastic}


def _yield_constants(n, radius, bead_youngs_pa, bead_poisson, driver_youngs_pa, driver_poisson, wall_youngs_pa,
                     wall_poisson, bead_yield_stress_pa) -> dict:
    """`from_materials`' constants of the elastic-plastic laws: the paper's mean-pressure
    yield force of every contact (N), the reduced radii (m), the beads' Poisson ratio and the
    yield stress (Pa)."""
    bead_theta = contact.theta(bead_youngs_pa, bead_poisson)
    face_theta = contact.theta(jnp.asarray([driver_youngs_pa] + [bead_youngs_pa] * (n - 1) + [wall_youngs_pa]),
                               jnp.asarray([driver_poisson] + [bead_poisson] * (n - 1) + [wall_poisson]))
    face_radius = jnp.asarray([np.inf] + [1.0] * (n - 1) + [np.inf]) * radius
    return {"contact_yield_force_n": contact.yield_force(bead_yield_stress_pa, radius, bead_theta, face_radius,
                                                          face_theta),
                "contact_reduced_radius_m": 1.0 / (1.0 / radius + 1.0 / face_radius),
                "contact_poisson": jnp.full((n + 1,), bead_poisson, dtype=jnp.float64),
                "yield_stress_pa": bead_yield_stress_pa}


def _describe_chain(chain: DrivenChain) -> dict:
    out = {name: np.asarray(getattr(chain, name)).tolist()
           for name in ("bead_mass_kg", "contact_kappa_n_m1p5", "precompression_n", "damping_rate_per_s")}
    out["eta_s"] = np.asarray(chain.eta_s).tolist()
    if type(chain.contact_law) is not laws.Hertz:
        out["contact_law"] = _describe_law(chain.contact_law)
    if [type(law) for law in chain.dissipation] != [laws.Viscoelastic]:
        out["dissipation"] = [_describe_law(law) for law in chain.dissipation]
    for name in ("support_friction", "drive_stroke"):
        if getattr(chain, name) is not None:
            out[name] = _describe_law(getattr(chain, name))
    for name in ("contact_yield_force_n", "contact_reduced_radius_m", "contact_poisson", "yield_stress_pa"):
        if getattr(chain, name) is not None:
            out[name] = np.asarray(getattr(chain, name)).tolist()
    return out


def _describe_law(law) -> dict:
    """A law as its type name and its fields (numbers as lists, nested laws likewise)."""
    out = {"type": type(law).__name__}
    for field in dataclasses.fields(law):
        value = getattr(law, field.name)
        out[field.name] = _describe_law(value) if isinstance(value, eqx.Module) else np.asarray(value).tolist()
    return out


def _concretely_inactive(law: laws.AbstractDissipation) -> bool:
    """Whether `law` concretely dissipates nothing (a traced coefficient may not be 0)."""
    leaves = jax.tree_util.tree_leaves(law)
    if not all(is_concrete(leaf) for leaf in leaves):
        return False
    with jax.ensure_compile_time_eval():  # concrete numbers, also while a caller's jit traces
        return not bool(np.any(np.asarray(law.is_active())))


def _dissipation(dissipation, eta_s) -> tuple[laws.AbstractDissipation, ...]:
    """The chain's dissipation laws: `dissipation` (a law or a sequence; None: the default
    `Viscoelastic`), with `eta_s` (s; None: not given) the coefficient of its `Viscoelastic`."""
    if dissipation is None:
        given = ()
    elif isinstance(dissipation, laws.AbstractDissipation):
        given = (dissipation,)
    else:
        given = tuple(dissipation)
    for law in given:
        if not isinstance(law, laws.AbstractDissipation):
            raise ValueError(f"dissipation: expected hertzchain.laws dissipation laws (e.g. "  # noqa: TRY004 (bad input is a ValueError here)
                             f"laws.Viscoelastic(eta_s=1e-6), laws.VelocitySquared(0.5)), got {law!r}.")
    kinds = [type(law) for law in given]
    for kind in set(kinds):
        if kinds.count(kind) > 1:
            raise ValueError(f"dissipation lists {kind.__name__} {kinds.count(kind)} times; give it once.")
    if eta_s is None:
        return given if dissipation is not None else (laws.Viscoelastic(0.0),)
    others = tuple(law for law in given if type(law) is not laws.Viscoelastic)
    if len(others) < len(given):
        raise ValueError("eta_s: give the Kuwabara-Kono time either as eta_s or as laws.Viscoelastic in dissipation, "
                         "not both.")
    return (laws.Viscoelastic(eta_s),) + others


def _check_law_parameters(chain_laws, n_contacts: int) -> None:
    """ValueError where a law's array parameter is neither one value nor one per contact
    (one per bead for the supports' law, `n_contacts` = n)."""
    for law in chain_laws:
        for leaf in jax.tree_util.tree_leaves(law):
            if jnp.shape(leaf) not in ((), (n_contacts,)):
                raise ValueError(f"{type(law).__name__}: every parameter must be one value or one per "
                                 f"{'bead' if isinstance(law, laws.IwanSupport) else 'contact'} ({n_contacts},), got "
                                 f"shape {jnp.shape(leaf)}.")


def _check_law_constants(chain: DrivenChain) -> None:
    """ValueError where the contact law reads a constant the chain does not have."""
    law = chain.contact_law
    while isinstance(law, laws.AbstractInSeries):  # what the inner law reads
        law = law.law
    needed = {laws.Thornton: ("contact_yield_force_n",),
              laws.JacksonGreen: ("contact_yield_force_n", "contact_reduced_radius_m", "contact_poisson",
                                  "yield_stress_pa")}.get(type(law), ())
    missing = [name for name in needed if getattr(chain, name) is None]
    if missing:
        raise ValueError(f"contact_law: {type(law).__name__} reads {', '.join(missing)}; give them (inf: a contact "
                         "that never yields), or build the chain with DrivenChain.from_materials(..., "
                         "bead_yield_stress_pa=...).")
    leaves = jax.tree_util.tree_leaves((chain.precompression_n, chain.contact_constants()))
    if law.has_history and all(is_concrete(leaf) for leaf in leaves):
        with jax.ensure_compile_time_eval():
            above = np.asarray(chain.static_force_n() > law.yield_force_n(chain.contact_constants()))
        if np.any(above):
            raise ValueError(f"precompression_n: the static force of contact(s) {np.flatnonzero(above).tolist()} is "
                             f"above the yield force of {type(law).__name__}; the static state is the elastic "
                             "(Hertz) one, so give a preload below yield (or a larger yield force).")
    for dissipation in chain.dissipation:
        if isinstance(dissipation, laws.Viscoelastic):
            check_positive_parameters("Viscoelastic", (("eta_s", dissipation.eta_s, "s"),), zero_ok=True)
