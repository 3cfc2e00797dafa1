"""The parameter registry: transforms, bounds, the C <-> mu* mapping, name checks."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain as hc
from fitting.parameters import (
    REGISTRY,
    ParameterInstance,
    ParameterSpec,
    bare_speed_constant,
    from_unbounded,
    get_spec,
    parse_parameter_list,
    register_parameter,
    to_unbounded,
    transform_arrays,
)
from hertzchain.theory import (
    DISCRETE_SPEED_FACTOR,
    LONG_WAVE_SPEED_FACTOR,
    long_wave_velocity_constant,
)


def test_required_parameters_are_registered():
    for name in ("eta", "mu", "C", "mu_star", "wall_youngs", "wall_poisson", "striker_velocity",
                 "time_offset", "gain", "precompression"):
        assert name in REGISTRY


def test_unknown_name_lists_the_valid_ones():
    with pytest.raises(ValueError, match="Unknown parameter 'etaa'.*eta, mu, C"):
        parse_parameter_list("eta,etaa")


def test_c_and_mu_star_are_exclusive():
    with pytest.raises(ValueError, match="same stiffness scale"):
        parse_parameter_list("C,mu_star")


@pytest.mark.parametrize(
    "beads",
    [{}, {"bead_radius_m": 0.005, "bead_density_kg_m3": 8960.0, "bead_youngs_pa": 130e9,
          "bead_poisson": 0.34, "mu_star": 0.05}],
)
def test_bare_speed_constant_against_eq3(beads):
    """C_0 over Eq. (3)'s C_t (from density and Young's modulus, not mass and kappa) is the
    ratio of the discrete and long-wave factors, whatever the beads and mu*."""
    setup = hc.ChainSetup(**beads)
    c_t = long_wave_velocity_constant(setup.bead_radius_m[0], setup.bead_density_kg_m3[0],
                                      setup.bead_youngs_pa[0], setup.bead_poisson[0])
    ratio = float(bare_speed_constant(setup) / c_t)
    assert ratio == pytest.approx(DISCRETE_SPEED_FACTOR / LONG_WAVE_SPEED_FACTOR, rel=1e-12)


def test_paper_bare_speed_constant():
    # The paper measures C = 201.5 +- 0.1 on its chain (Job et al., PRL 94, 178002).
    assert float(bare_speed_constant(hc.ChainSetup())) == pytest.approx(201.5, rel=1e-3)


def test_speed_constant_maps_exactly_onto_the_stiffness_scale():
    spec = get_spec("C")
    setup = hc.ChainSetup()
    target = 205.0
    fitted = spec.apply(setup, jnp.asarray(target))
    one_plus = float(1 + fitted.mu_star)
    # C is proportional to (1+mu*)^(1/3) exactly
    assert one_plus == pytest.approx((target / 201.3849) ** 3, rel=1e-4)
    assert spec.read(fitted) == pytest.approx(target, rel=1e-12)
    ratio = float(fitted.contact_kappa()[3] / setup.contact_kappa()[3])
    assert ratio == pytest.approx(one_plus, rel=1e-12)


def test_transform_round_trip_and_bounds():
    instances = [ParameterInstance(get_spec(n), label=n) for n in ("eta", "mu", "C", "time_offset", "wall_poisson")]
    x = np.array([2e-6, 0.19, 201.5, -3e-6, 0.3])
    z = to_unbounded(instances, x)
    back = np.asarray(from_unbounded(tuple(jnp.asarray(a) for a in transform_arrays(instances)), jnp.asarray(z)))
    np.testing.assert_allclose(back, x, rtol=1e-12, atol=1e-18)
    # any z maps inside the bounds
    constants = tuple(jnp.asarray(a) for a in transform_arrays(instances))
    far = np.asarray(from_unbounded(constants, jnp.full(5, 1e3)))
    for inst, value in zip(instances, far):
        assert inst.spec.lower * (1 - 1e-12) <= value <= inst.spec.upper * (1 + 1e-12)
    # near the centre the transform is the identity in log / scale units
    slope = jax.jacfwd(lambda zz: jnp.log(from_unbounded(constants, zz)[0]))(jnp.asarray(z))[0]
    assert 0.7 < float(slope) <= 1.0


def test_start_outside_bounds_is_refused():
    with pytest.raises(ValueError, match="outside its bounds"):
        to_unbounded([ParameterInstance(get_spec("mu"), label="mu")], [5.0])


def test_register_a_new_parameter():
    spec = ParameterSpec("test_extra_strength", "", "global", "linear", -1.0, 1.0, kind="extra",
                         description="a model switch")
    try:
        register_parameter(spec)
        assert get_spec("test_extra_strength") is spec
        with pytest.raises(ValueError, match="already registered"):
            register_parameter(spec)
    finally:
        REGISTRY.pop("test_extra_strength", None)
    assert math.isfinite(spec.transform_constants()[1])
