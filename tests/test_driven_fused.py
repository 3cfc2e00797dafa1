"""The fused host kernel of driven lock-in grids (`hertzchain.driven.fused`) against the JAX
kernel (`kernel="jax"`): values, forward-mode derivatives and batching rules.

The JAX kernel is itself held to scipy's DOP853, closed forms and balances
(`tests/test_driven*.py`, which run the fused kernel by default wherever it builds)."""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hertzchain import native
from hertzchain.driven import DrivenChain, fused, lockin_grid

# Skipped only where the kernel cannot be built at all (no compiler, switched off, not a
# CPU); a kernel that fails to build fails `test_the_kernel_builds_where_a_compiler_is`.
_CANNOT = (native.build._cxx() is None or os.environ.get("HERTZCHAIN_NATIVE", "1") == "0"
           or jax.default_backend() != "cpu")
pytestmark = pytest.mark.skipif(_CANNOT, reason="no C++ compiler, HERTZCHAIN_NATIVE=0 or not a CPU")

# Not the fits' steel beads: unequal contacts, a light and a heavy bead, and a third bead
CHAINS = {
    "one_bead_undamped_contacts": (np.array([0.028]), np.array([1.2e10, 1.5e10]), 0.5, 800.0, 0.0),
    "two_beads_kuwabara_kono": (np.array([0.028, 0.011]), np.array([1.4e10, 9e9, 1.3e10]), 0.2, 500.0, 1e-6),
    "three_beads_opening_contacts": (np.array([0.01, 0.02, 0.015]), np.array([8e9, 1e10, 1.1e10, 9e9]), 0.05,
                                     300.0, 2e-7),
}
# Round-off grows through a run where contacts open and close (each opening a kink of the
# force): the three-bead chain's runs at 60 nm end 2e-12 apart (of the largest amplitude),
# the others within 1e-15.
TOLERANCE = {"one_bead_undamped_contacts": 1e-13, "two_beads_kuwabara_kono": 1e-13, "three_beads_opening_contacts": 1e-10}
FREQUENCIES_HZ = np.linspace(1500.0, 6500.0, 23)
# up to 60 nm: the contacts of the three-bead chain (static overlaps of a few nm) open
DRIVES_M = np.array([1e-9, 8e-9, 6e-8])
SETTINGS = dict(harmonics=(1.0, 0.5), ramp_periods=10, hold_periods=12, window_periods=4, steps_per_period=48)


def test_the_kernel_builds_where_a_compiler_is():
    assert fused.unavailable_reason() is None
    assert fused.runs("velocity") and fused.runs("displacement") and not fused.runs("force")


def _chain(name):
    return DrivenChain(*CHAINS[name])


def _relative(a, b):
    return float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b)))


# each chain read one way in the default suite, the other way with `-m slow` (default-suite time)
@pytest.mark.parametrize(("quantity", "name"), [
    (q, n) if (q == "velocity") == (i % 2 == 0) else pytest.param(q, n, marks=pytest.mark.slow)
    for i, n in enumerate(CHAINS) for q in ("velocity", "displacement")])
def test_grid_equals_the_jax_kernel(name, quantity):
    """Complex amplitudes at the drive and its subharmonic, every bead read: the same
    arithmetic, summed in another order, so equal to round-off."""
    chain = _chain(name)
    for bead in range(1, chain.n_beads + 1):
        kw = dict(SETTINGS, bead=bead, quantity=quantity)
        reference = lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, kernel="jax", **kw).complex_amplitude
        fused_grid = lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, **kw).complex_amplitude
        assert _relative(fused_grid, reference) < TOLERANCE[name]


def test_a_grid_without_a_ramp_equals_the_jax_kernel():
    """ramp_periods = 0: the drive at its amplitude from the first step."""
    kw = dict(SETTINGS, ramp_periods=0, bead=2)
    chain = _chain("two_beads_kuwabara_kono")
    reference = lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, kernel="jax", **kw).complex_amplitude
    assert _relative(lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, **kw).complex_amplitude, reference) < 1e-12


# with `-m slow` (suite time): the values are held to the JAX kernel by the grid test above, the
# derivatives by the JVP and vmap-of-jacfwd tests below
@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.slow)
                                  for name in ("one_bead_undamped_contacts", "three_beads_opening_contacts")])
def test_jacobians_equal_jacfwd_through_the_jax_kernel(name):
    """`jax.jacfwd` in every field of the chain (masses, stiffnesses, precompression,
    damping, eta), in the frequencies (each run's step and angular frequency) and in the
    drive amplitudes."""
    chain = _chain(name)

    def rms(c, f, a, kernel):
        return lockin_grid(c, f, a, kernel=kernel, bead=chain.n_beads, **SETTINGS).rms

    f, a = jnp.asarray(FREQUENCIES_HZ), jnp.asarray(DRIVES_M)
    for argnum in (0, 1, 2):
        reference = jax.tree_util.tree_leaves(jax.jacfwd(rms, argnums=argnum)(chain, f, a, "jax"))
        fused_jacobian = jax.tree_util.tree_leaves(jax.jacfwd(rms, argnums=argnum)(chain, f, a, "auto"))
        for ours, theirs in zip(fused_jacobian, reference, strict=True):
            assert _relative(ours, theirs) < 100 * TOLERANCE[name]


def test_jvp_and_linearize_equal_a_jacobian_column():
    chain = _chain("two_beads_kuwabara_kono")
    kw = dict(SETTINGS, bead=1)

    def rms(gamma):
        return lockin_grid(DrivenChain(chain.bead_mass_kg, chain.contact_kappa_n_m1p5, chain.precompression_n,
                                       gamma, chain.eta_s), FREQUENCIES_HZ, DRIVES_M, **kw).rms

    column = jax.jacfwd(rms)(jnp.asarray(500.0))
    value, tangent = jax.jvp(rms, (jnp.asarray(500.0),), (jnp.asarray(1.0),))
    linear_value, linear = jax.linearize(rms, jnp.asarray(500.0))
    assert _relative(tangent, column) < 1e-14
    assert _relative(linear(jnp.asarray(1.0)), column) < 1e-14
    assert _relative(linear_value, value) < 1e-14
    assert _relative(value, lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, kernel="jax", **kw).rms) < 1e-12


def test_vmap_over_chains_and_jacfwd_of_it_are_one_kernel_call():
    """A vmapped batch of chains joins the kernel's runs, a jacfwd's basis its directions:
    one custom call and no loop in the compiled program, numbers as the chains one by one."""
    base = _chain("two_beads_kuwabara_kono")
    kw = dict(SETTINGS, bead=2)

    def rms(gamma, precompression):
        c = DrivenChain(base.bead_mass_kg, base.contact_kappa_n_m1p5, precompression, gamma, base.eta_s)
        return lockin_grid(c, FREQUENCIES_HZ, DRIVES_M, **kw).rms

    gammas, loads = jnp.array([300.0, 700.0]), jnp.array([0.2, 0.35])
    batched = jax.vmap(rms)(gammas, loads)
    jacobian = jax.vmap(jax.jacfwd(rms, argnums=(0, 1)))(gammas, loads)
    for i in range(2):
        one = DrivenChain(base.bead_mass_kg, base.contact_kappa_n_m1p5, loads[i], gammas[i], base.eta_s)
        assert _relative(batched[i], lockin_grid(one, FREQUENCIES_HZ, DRIVES_M, kernel="jax", **kw).rms) < 1e-12
        single = jax.jacfwd(rms, argnums=(0, 1))(gammas[i], loads[i])
        for ours, theirs in zip(jacobian, single, strict=True):
            assert _relative(ours[i], theirs) < 1e-13
    program = jax.jit(jax.vmap(jax.jacfwd(rms, argnums=(0, 1)))).lower(gammas, loads).as_text()
    assert program.count("hertzchain_driven_lockin_tangent") == 1
    assert "hertzchain_driven_lockin\"" not in program and "while" not in program


def test_force_readings_and_kernel_jax_run_the_jax_kernel():
    """The kernel reads beads only: a contact's force takes the JAX kernel, bit for bit."""
    chain = _chain("two_beads_kuwabara_kono")
    kw = dict(SETTINGS, quantity="force", contact=1)
    assert not fused.runs("force")
    auto = lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, **kw).complex_amplitude
    np.testing.assert_array_equal(auto, lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, kernel="jax",
                                                    **kw).complex_amplitude)
    with pytest.raises(ValueError, match="kernel"):
        lockin_grid(chain, FREQUENCIES_HZ, DRIVES_M, kernel="cuda", **kw)
