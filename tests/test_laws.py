"""Contact and dissipation laws as types: each law against its closed form, its tangent
stiffness and energy against finite differences, the registry against the native kernels'
names, and `ChainSetup`'s former keywords against the law objects they stand for."""

import inspect
import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain as hc
from hertzchain import laws, native
from hertzchain.batched import KernelFlags

KAPPA = 1.2e10  # N/m^1.5, about two 13 mm steel beads
OVERLAPS = np.array([-1e-6, 0.0, 2e-7, 3e-6, 2e-5])
CONSTANTS = laws.ContactConstants(jnp.asarray(KAPPA))


def _plastic_constants(setup):
    """Every contact's constants of `setup` as its model gives them (bead-bead contact 1)."""
    constants = setup.contact_constants()
    return laws.ContactConstants(constants.kappa_n_m1p5[1], setup.contact_yield_force_n()[1],
                                 constants.reduced_radius_m[1], constants.poisson[1], constants.yield_stress_pa)


def test_hertz_and_power_law_follow_their_closed_forms():
    delta = np.clip(OVERLAPS, 0.0, None)
    np.testing.assert_allclose(laws.Hertz().force(OVERLAPS, None, CONSTANTS), KAPPA * delta**1.5, rtol=1e-14)
    np.testing.assert_allclose(laws.Hertz().energy(OVERLAPS, None, CONSTANTS), 0.4 * KAPPA * delta**2.5,
                               rtol=1e-14)
    n, ref = 1.3, 4e-6
    law = laws.PowerLaw(n, ref)
    np.testing.assert_allclose(law.force(OVERLAPS, None, CONSTANTS), KAPPA * ref**1.5 * (delta / ref) ** n,
                               rtol=1e-13)
    assert float(law.force(ref, None, CONSTANTS)) == pytest.approx(KAPPA * ref**1.5, rel=1e-14)


@pytest.mark.parametrize("law", [laws.Hertz(), laws.PowerLaw(1.7, 2e-6)], ids=["hertz", "power_law"])
def test_tangent_stiffness_energy_and_inverse_of_elastic_laws(law):
    delta = jnp.asarray([3e-7, 4e-6, 1.5e-5])
    h = 1e-4 * delta
    central = (law.force(delta + h, None, CONSTANTS) - law.force(delta - h, None, CONSTANTS)) / (2 * h)
    np.testing.assert_allclose(law.tangent_stiffness(delta, None, CONSTANTS), central, rtol=1e-7)
    # the force is the derivative of the energy
    energy_slope = (law.energy(delta + h, None, CONSTANTS) - law.energy(delta - h, None, CONSTANTS)) / (2 * h)
    np.testing.assert_allclose(energy_slope, law.force(delta, None, CONSTANTS), rtol=1e-7)
    forces = jnp.asarray([0.0, 1.0, 250.0])
    np.testing.assert_allclose(law.force(law.overlap_at_force(forces, CONSTANTS), None, CONSTANTS), forces,
                               rtol=1e-13, atol=1e-30)


def test_hertz_stiffness_at_a_static_force_is_the_linearised_law():
    """$dF/d\\delta = \\tfrac32\\kappa^{2/3}F_0^{1/3}$ (what the driven chains and the
    diagnosis linearise about)."""
    forces = np.array([0.5, 4.5, 100.0])
    np.testing.assert_allclose(laws.Hertz().stiffness_at_force(forces, CONSTANTS),
                               1.5 * KAPPA ** (2 / 3) * forces ** (1 / 3), rtol=1e-14)


@pytest.mark.parametrize("law", [laws.Thornton(), laws.JacksonGreen()], ids=["thornton", "jackson_green"])
def test_plastic_laws_yield_remember_their_largest_overlap_and_unload_stiffer(law):
    setup = hc.ChainSetup(3, contact_law=law)
    constants = _plastic_constants(setup)
    kappa = float(constants.kappa_n_m1p5)
    yield_overlap = float(law.overlap_at_force(law.yield_force_n(constants), constants))
    # below yield: Hertz, no history
    below = 0.5 * yield_overlap
    assert float(law.force(below, below, constants)) == pytest.approx(kappa * below**1.5, rel=1e-12)
    # beyond yield: softer than Hertz on loading, dissipation > 0, the history is the largest overlap
    peak = 8.0 * yield_overlap
    state = law.update_state(law.initial_state(jnp.asarray(below)), jnp.asarray(peak))
    assert float(state) == peak and float(law.update_state(state, 0.5 * peak)) == peak
    force, _, dissipated = law.parts(peak, state, constants)
    assert float(force) < kappa * peak**1.5 and float(dissipated) > 0.0
    # unloading at fixed history: stiffer than Hertz at the same force, as finite differences say
    delta = 0.97 * peak
    h = 1e-5 * peak
    central = (law.force(delta + h, state, constants) - law.force(delta - h, state, constants)) / (2 * h)
    tangent = float(law.tangent_stiffness(delta, state, constants))
    assert tangent == pytest.approx(float(central), rel=1e-6)
    assert tangent > float(laws.Hertz().stiffness_at_force(law.force(delta, state, constants), constants))


def test_thornton_yields_at_the_papers_mean_pressure_force():
    """$F_Y = (\\pi\\sigma_Y)^3(R^*(\\theta+\\theta'))^2$, about 470 N for the paper's beads."""
    setup = hc.ChainSetup(3, contact_law=laws.Thornton())
    theta = 3 * (1 - 0.3**2) / (4 * 203e9)
    expected = (math.pi * 2e9) ** 3 * (0.0065 * 2 * theta) ** 2
    assert float(setup.contact_yield_force_n()[1]) == pytest.approx(expected, rel=1e-12)
    assert 450 < expected < 500


def test_dissipation_laws_add_their_closed_forms_and_never_pull():
    eta, gamma = 2e-6, 30.0
    delta = jnp.asarray([-1e-6, 4e-6, 4e-6, 4e-6])
    rate = jnp.asarray([0.1, 0.1, -0.01, -50.0])
    elastic = laws.Hertz().force(delta, None, CONSTANTS)
    total = laws.total_force(elastic, delta, rate, KAPPA, (laws.Viscoelastic(eta), laws.Dashpot(gamma)))
    expected = KAPPA * 4e-6**1.5 + (1.5 * eta * KAPPA * 4e-6**0.5 + gamma) * np.asarray(rate)
    np.testing.assert_allclose(total[1:3], expected[1:3], rtol=1e-13)
    assert float(total[0]) == 0.0 and float(total[3]) == 0.0  # open contact; fast unloading: separation
    assert laws.total_force(elastic, delta, rate, KAPPA, ()) is elastic
    assert not bool(laws.is_damped((laws.Viscoelastic(0.0), laws.Dashpot(0.0))))
    assert bool(laws.is_damped((laws.Viscoelastic(0.0), laws.Dashpot(gamma))))


def test_registry_names_every_law_as_the_native_kernels_know_it():
    contact_names = {laws.registry.native_name(law()) for law in (laws.Hertz, laws.PowerLaw, laws.Thornton,
                                                                  laws.JacksonGreen)}
    assert contact_names == set(native.CONTACT_LAWS)
    for name in native.CONTACT_LAWS:
        assert laws.registry.native_name(laws.registry.contact_law_named(name)()) == name
    # Kuwabara-Kono damping is the kernels' `viscous`; the rate slot's laws are `rate_law`'s values
    assert laws.Viscoelastic().native_name in KernelFlags._fields
    assert {laws.Dashpot().native_name, laws.VelocitySquared().native_name} == set(native.RATE_LAW_DEFINES)
    # the rate slot's laws give the kernels their coefficient, the others none
    for law in (laws.Viscoelastic(2e-6), laws.Dashpot(30.0), laws.VelocitySquared(5.0)):
        coefficient = law.rate_slot_coefficient()
        assert (coefficient is not None) == (law.native_name in native.RATE_LAW_DEFINES)
        if coefficient is not None:  # its force is the coefficient times the rate (velocity squared: |rate| too)
            rate = -0.3
            per_rate = coefficient * (abs(rate) if law.native_name == "velocity_squared" else 1.0)
            assert float(law.force(1e-6, rate, 1e10)) == pytest.approx(float(per_rate) * rate, rel=1e-15)
    with pytest.raises(ValueError, match="no contact law is named 'hertzian'"):
        laws.registry.contact_law_named("hertzian")


@pytest.mark.parametrize("old, law", [
    (dict(plasticity=True), laws.Thornton),
    (dict(plasticity=True, plastic_law="jackson_green"), laws.JacksonGreen),
    (dict(contact_exponent=1.6, exponent_reference_overlap_m=3e-6), laws.PowerLaw),
    (dict(power_law=False, contact_exponent=1.6), laws.Hertz),
])
def test_former_keywords_warn_and_build_the_law(old, law):
    with pytest.warns(DeprecationWarning, match=f"contact_law=hertzchain.laws.{law.__name__}") as record:
        setup = hc.ChainSetup(4, **old)
    # attributed to this line (equinox's __init__ wrapper in between), so Python's default
    # filters show it in a user's script
    assert [(w.filename, w.lineno) for w in record] == [(__file__, inspect.currentframe().f_lineno - 3)]
    assert type(setup.contact_law) is law
    assert setup.plasticity == old.get("plasticity", False)
    if law is laws.PowerLaw:
        assert float(setup.contact_exponent) == 1.6 and float(setup.exponent_reference_overlap_m) == 3e-6


def test_setup_takes_law_objects_and_keeps_its_former_fields_readable():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        setup = hc.ChainSetup(4, contact_law=laws.PowerLaw(1.4), dissipation=laws.Dashpot(7.0), eta_s=1e-6)
    assert (float(setup.eta_s), float(setup.dashpot_n_s_m)) == (1e-6, 7.0)
    assert setup.power_law and not setup.plasticity and float(setup.contact_exponent) == 1.4
    assert [type(law) for law in setup.dissipation] == [laws.Viscoelastic, laws.Dashpot]
    with pytest.raises(ValueError, match="Give contact_law only: plasticity"):
        hc.ChainSetup(4, contact_law=laws.Hertz(), plasticity=True)
    with pytest.raises(ValueError, match="contact_law must be a hertzchain.laws contact law"):
        hc.ChainSetup(4, contact_law="hertz")
    with pytest.raises(ValueError, match="dissipation lists Dashpot 2 times"):
        hc.ChainSetup(4, dissipation=(laws.Dashpot(1.0), laws.Dashpot(2.0)))
    with pytest.raises(ValueError, match="contact_exponent must be between 1 and 3"):
        hc.ChainSetup(4, contact_law=laws.PowerLaw(5.0))
