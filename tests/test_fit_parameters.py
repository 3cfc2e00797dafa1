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
    with pytest.raises(ValueError, match="Unknown parameter 'etaa'.*eta_s, mu, C"):
        parse_parameter_list("eta_s,etaa")


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


def test_material_nuisances_are_applied_before_the_speed_constant():
    """With C fitted, a stiffer bead material changes only the contacts C does not set.

    C fixes the bead-bead stiffness scale (1 + mu*) kappa through Eq. 3's discrete
    constant, so raising the beads' Young's modulus by 10 % at fixed C must leave the
    bead-bead contacts' stiffness where it was (the scale 1 + mu* drops by 1/1.1), and
    change the wall contact by the ratio of the Hertz kappa_w ~ sqrt(R) / (theta + theta_w)
    times that scale.
    """
    from fitting.fit import make_problem
    from fitting.synthetic import paper_setups, synthetic_traces

    trace = synthetic_traces(paper_setups([0.3]), contacts=(6,), t_end_s=1.5e-3)[0]
    problem = make_problem([trace], ("C", "bead_youngs_pa"))
    c = float(bare_speed_constant(problem.base_setups[0])) * 1.02
    youngs = 203e9
    before = problem.setup_at(np.array([c, youngs]), 0)
    after = problem.setup_at(np.array([c, 1.1 * youngs]), 0)
    # contact_kappa includes the stiffness scale (1 + mu*): contact 1 is bead 1 on bead 2
    assert float(after.contact_kappa()[1]) == pytest.approx(float(before.contact_kappa()[1]), rel=1e-12)
    theta = lambda y, nu: 3 * (1 - nu**2) / (4 * y)  # noqa: E731
    wall = before.wall_youngs_pa
    ratio = (theta(youngs, 0.3) + theta(wall, before.wall_poisson)) / (
        theta(1.1 * youngs, 0.3) + theta(wall, before.wall_poisson))
    scale = float((1 + after.mu_star) / (1 + before.mu_star))
    assert scale == pytest.approx(1 / 1.1, rel=1e-12)
    wall_ratio = float(after.wall_kappa() / before.wall_kappa())
    assert wall_ratio == pytest.approx(float(ratio) * scale, rel=1e-12)
    assert abs(wall_ratio - 1) > 0.02  # the wall contact does change: C cannot absorb it


def test_bead_radius_scales_every_bead_and_its_mass():
    from fitting.fit import make_problem
    from fitting.synthetic import paper_setups, synthetic_traces

    trace = synthetic_traces(paper_setups([0.3]), contacts=(6,), t_end_s=1.5e-3)[0]
    problem = make_problem([trace], ("bead_radius_m",))
    setup = problem.setup_at(np.array([0.013 * 1.01]), 0)
    assert np.allclose(np.asarray(setup.bead_radius_m), 0.013 * 1.01, rtol=1e-12)
    assert float(setup.bead_mass_kg[0]) == pytest.approx(
        4 / 3 * math.pi * 7780 * (0.013 * 1.01) ** 3, rel=1e-12)
    assert float(setup.striker_radius_m) == pytest.approx(float(problem.base_setups[0].striker_radius_m))


def test_sensor_gain_is_one_number_per_channel_name_across_files():
    from fitting.fit import make_problem
    from fitting.synthetic import paper_setups, synthetic_traces

    traces = synthetic_traces(paper_setups([0.2, 0.4]), contacts=(6,), t_end_s=1.5e-3)
    problem = make_problem(traces, ("sensor_gain",))
    assert problem.labels == ("sensor_gain[contact_6]", "sensor_gain[wall]")
    base = np.asarray(problem.model_vector(np.array([1.0, 1.0])))
    scaled = np.asarray(problem.model_vector(np.array([1.03, 1.0])))
    for slices in problem.residual_slices():
        np.testing.assert_allclose(scaled[slices["contact_6"]], 1.03 * base[slices["contact_6"]], rtol=1e-12)
        np.testing.assert_allclose(scaled[slices["wall"]], base[slices["wall"]], rtol=1e-12)
