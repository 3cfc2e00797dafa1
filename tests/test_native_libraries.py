"""The table of host libraries (`native.libraries`): which library runs which physics, their
macros and FFI targets, against the combinations written out here."""

import numpy as np
import pytest

from hertzchain import native
from hertzchain.batched import KernelFlags
from hertzchain.native import libraries

OTHER_LAWS = ("power_law", "thornton", "jackson_green")


def _expected(law, rate, sensors):
    """The library that runs each combination, as `chain_kernel.cc`'s macros build them: the
    rate slot's laws are compiled in on Hertz contacts without sensors; the other laws' and
    the sensors' libraries run a dashpot as a runtime term; velocity-squared dissipation runs
    on Hertz contacts without sensors only."""
    if rate == "velocity_squared":
        return "velocity_squared" if law == "hertz" and not sensors else None
    if sensors:
        return "compliant sensors" if law == "hertz" else f"{law} compliant sensors"
    if law != "hertz":
        return law
    return "dashpot" if rate == "dashpot" else "chain"


@pytest.mark.parametrize("law", ("hertz",) + OTHER_LAWS)
@pytest.mark.parametrize("rate", (None, "dashpot", "velocity_squared"))
@pytest.mark.parametrize("sensors", (False, True))
def test_each_combination_of_law_rate_and_sensors_has_its_one_library(law, rate, sensors):
    library = native.host_library_for(law, rate, sensors)
    assert (library.name if library else None) == _expected(law, rate, sensors)
    matches = [lib for lib in native.HOST_LIBRARIES.values()
               if lib.law == law and lib.sensors == sensors and rate in lib.rates]
    assert len(matches) == (library is not None)
    flags = KernelFlags(springs=False, preload=False, viscous=rate is not None, rate_law=rate,
                        law=law, sensors=(3,) if sensors else ())
    assert native.host.host_library_of(flags) == library


def test_the_libraries_macros_and_targets():
    """Every library compiles from its own macros (one cached file each) and registers
    targets no other library does; the names are those the handlers are called by."""
    table = native.HOST_LIBRARIES
    assert list(table) == ["chain", "dashpot", "velocity_squared", "compliant sensors", *OTHER_LAWS,
                           *(f"{law} compliant sensors" for law in OTHER_LAWS)]
    assert table["chain"].defines == ()
    assert table["velocity_squared"].defines == ("-DHC_DASHPOT_LIBRARY", "-DHC_VELOCITY_SQUARED_LIBRARY")
    assert table["power_law compliant sensors"].defines == ("-DHC_POWER_LIBRARY", "-DHC_SENSOR_LIBRARY")
    assert len({lib.defines for lib in table.values()}) == len(table)
    targets = [target for lib in table.values() for target, _ in lib.targets]
    assert len(set(targets)) == len(targets)
    assert table["chain"].targets == (
        ("hertzchain_chain_forward", "HertzChainForward"), ("hertzchain_chain_full_forward", "HertzChainFullForward"),
        ("hertzchain_chain_full_tangent", "HertzChainFullTangent"), ("hertzchain_chain_full_books", "HertzChainFullBooks"))
    assert table["dashpot"].target("books") == "hertzchain_chain_full_books_dashpot"
    assert table["thornton compliant sensors"].target("tangent") == "hertzchain_chain_full_tangent_thornton_sensors"
    with pytest.raises(ValueError, match="holds no 'books' runs"):
        table["compliant sensors"].target("books")
    assert (native.TARGET, native.FULL_TARGET) == ("hertzchain_chain_forward", "hertzchain_chain_full_forward")
    # the thread kernels run Hertz contacts, with or without a dashpot, and no sensors
    assert [name for name, lib in table.items() if lib.runs_on_threads] == ["chain", "dashpot"]


def test_a_law_or_rate_it_does_not_know_is_refused_by_name():
    with pytest.raises(ValueError, match="law must be one of"):
        native.host_library_for("hooke")
    with pytest.raises(ValueError, match="rate must be None or one of"):
        native.host_library_for("hertz", "coulomb")


def test_kernel_for_refuses_the_combinations_no_library_runs():
    """Velocity-squared dissipation with compliant sensors or on another law, and the books of
    compliant sensors, run on the JAX kernel (`kernel_for` is None) without building anything."""
    for flags in (KernelFlags(springs=False, preload=False, viscous=True, rate_law="velocity_squared", sensors=(2,), ledger=False),
                  KernelFlags(springs=False, preload=False, viscous=True, rate_law="velocity_squared", law="thornton"),
                  KernelFlags(springs=False, preload=False, viscous=True, sensors=(2,), ledger=True)):
        assert native.kernel_for(flags, None) is None
    assert libraries.host_library_for("hertz", "dashpot", True).name == "compliant sensors"


def test_each_contact_laws_parameters_fill_the_rows_the_kernel_reads():
    """`native.run_full`'s law array from each law's `native_rows`: the rows `chain_kernel.cc`'s
    `LawRows` reads (Hertz 2 of zeros, the power law 2, Thornton one per contact, Jackson-Green
    three per contact and 2), in its order."""
    import jax.numpy as jnp

    from hertzchain.native.calls import _law_array

    contacts = 4
    per_contact = lambda value: jnp.full((contacts, 1), value)  # noqa: E731
    p = {"kappa": per_contact(1e10), "exponent": jnp.full((1,), 1.6), "reference_overlap_m": jnp.full((1,), 2e-6),
         "yield_force_n": per_contact(50.0), "reduced_radius_m": per_contact(5e-3), "poisson": per_contact(0.3),
         "yield_stress_pa": jnp.full((1,), 1e9)}
    rows = {law: np.asarray(_law_array(p, law))[:, 0] for law in ("hertz",) + OTHER_LAWS}
    np.testing.assert_array_equal(rows["hertz"], [0.0, 0.0])
    np.testing.assert_array_equal(rows["power_law"], [1.6, 2e-6])
    np.testing.assert_array_equal(rows["thornton"], [50.0] * contacts)
    np.testing.assert_array_equal(rows["jackson_green"], [50.0] * contacts + [5e-3] * contacts + [0.3] * contacts
                                  + [1e9, 2.84])
