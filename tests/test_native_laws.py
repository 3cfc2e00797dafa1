"""Every contact law on the host's full C++ kernels against the JAX kernel: values and
`jax.jacfwd` (the laws run on dual numbers in `chain_laws.h`) in the law's own parameters,
on small chains and few steps.

The combinations held here are those no other default test holds to the JAX kernel
directly: Thornton's and Jackson-Green's laws on the full kernel (damped, frictional, with a
dashpot, preloaded), and Thornton's and the power law's on the compliant sensors' libraries.
(The power law's full runs: `test_native.py`; Jackson-Green's sensors: `test_compliant_sensor.py`.)
In the slow suite: each test takes tens of seconds, mostly XLA compiling the reference (the
JAX kernel's `jacfwd`; Thornton's full run: 29 s of CPU), beyond the libraries' builds.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import NEEDS_A_COMPILER

import hertzchain as hc
from hertzchain import laws, native
from hertzchain.batched import kernel_flags, record_batched
from hertzchain.compliant_sensor import CompliantSensors
from hertzchain.integrate import Recording

pytestmark = NEEDS_A_COMPILER

# Yield stress (Pa) low enough that the faster strikers yield the first contacts.
YIELD_PA = 1.2e9
LAWS = {"thornton": laws.Thornton(), "jackson_green": laws.JacksonGreen(), "power_law": laws.PowerLaw(1.6, 2e-6)}


def _assert_columns_close(ours, reference, rtol):
    """Each Jacobian column (last axis) of `ours` within `rtol` of its largest entry in
    `reference`, which must move."""
    ours, reference = np.asarray(ours), np.asarray(reference)
    for i in range(reference.shape[-1]):
        scale = np.max(np.abs(reference[..., i]))
        assert scale > 0.0, f"direction {i} moves nothing"
        np.testing.assert_allclose(ours[..., i], reference[..., i], rtol=0, atol=rtol * scale)


def _chain(law: str, **changes):
    """Three 6-bead chains (0.3, 3 and 1.5 m/s strikers) on `law`, and a 0.12 ms grid."""
    setup, _ = hc.batch_setup(hc.ChainSetup(6, contact_law=LAWS[law], bead_yield_stress_pa=YIELD_PA, **changes),
                              striker_velocity_m_s=[0.3, 3.0, 1.5])
    return setup, hc.choose_time_grid(setup, t_end_s=0.12e-3, sample_interval_s=2e-6)


@pytest.mark.slow
@pytest.mark.parametrize("law", ["thornton", "jackson_green"])
def test_elastic_plastic_full_runs_and_jacfwd_equal_the_jax_kernel(law):
    """The law's full library, damped, frictional, with a dashpot and a preload: forces and
    `jax.jacfwd` in damping, the dashpot, the yield stress, the impact speed and the beads'
    Poisson ratio (the unloading curves' tangents, carried from the peaks) equal the JAX
    kernel's to 1e-10 of each column's largest; the fast strikers yield the contacts."""
    base, grid = _chain(law, eta_s=1e-6, dashpot_n_s_m=0.5, mu=0.1, precompression_n=1.0)
    flags = kernel_flags(base)._replace(ledger=False)
    assert flags.law == law and flags.rate_law == "dashpot"

    def traced(q, kernel):
        ones = jnp.ones(base.eta_s.shape)
        setup = eqx.tree_at(
            lambda s: (s.dissipation[0].eta_s, s.dissipation[1].gamma_n_s_m, s.bead_yield_stress_pa,
                       s.striker_velocity_m_s, s.bead_poisson), base,
            (q[0] * ones, q[1] * ones, q[2] * ones, q[3] * base.striker_velocity_m_s, q[4] * base.bead_poisson))
        out = record_batched(setup, grid, Recording((0, 3)), flags, kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([1e-6, 0.5, YIELD_PA, 1.0, 1.0])

    def evaluation(kernel):
        return jax.jit(lambda q: (traced(q, kernel), jax.jacfwd(lambda q: traced(q, kernel))(q)))

    fused = evaluation("auto")
    assert fused.lower(q).as_text().count(f"custom_call @{native.HOST_LIBRARIES[law].target('tangent')}") == 1
    (forces, jac), (expected_forces, expected) = fused(q), evaluation("jax")(q)
    np.testing.assert_allclose(forces, expected_forces, rtol=0, atol=1e-12 * np.max(np.abs(expected_forces)))
    _assert_columns_close(jac, expected, 1e-10)
    yield_n = float(hc.ChainSetup(6, contact_law=LAWS[law], bead_yield_stress_pa=YIELD_PA).contact_yield_force_n()[0])
    assert np.max(np.asarray(forces)[0, 1]) > 1.5 * yield_n  # the 3 m/s striker's first contact yields


@pytest.mark.slow
@pytest.mark.parametrize("law", ["thornton", "power_law"])
def test_compliant_sensor_runs_and_jacfwd_on_the_law_equal_the_jax_kernel(law):
    """The law's compliant-sensor library, damped: forces and `jax.jacfwd` in the sensors'
    mass fraction and 1/omega0^2, damping and the law's own parameter (the yield stress; the
    exponent) equal the JAX kernel's to 1e-10 of each column's largest."""
    base, grid = _chain(law, eta_s=1e-7)
    beads = (2, 3)
    flags = kernel_flags(base)._replace(ledger=False, sensors=beads)
    assert native.kernel_for(flags, None) == native.FusedKernel("full", "host") and flags.law == law

    def traced(q, kernel):
        ones = jnp.ones(base.eta_s.shape)
        own = (lambda s: s.bead_yield_stress_pa) if law == "thornton" else (lambda s: s.contact_law.exponent)
        setup = eqx.tree_at(lambda s: (s.dissipation[0].eta_s, own(s)), base,
                            (q[2] * ones, q[3] * ones))
        sensors = CompliantSensors(beads, q[0] * ones, q[1] * 1e-12 * ones)
        out = record_batched(setup, grid, Recording((1, 2, 3)), flags, compliant_sensors=sensors, kernel=kernel)
        return jnp.stack([out.forces_n[name] for name in out.channel_names])

    q = jnp.asarray([0.3, 3.0, 1e-7, YIELD_PA if law == "thornton" else 1.6])
    fused = jax.jit(lambda q: (traced(q, "auto"), jax.jacfwd(lambda q: traced(q, "auto"))(q)))
    assert fused.lower(q).as_text().count(f"custom_call @{native.HOST_LIBRARIES[law + ' compliant sensors'].target('tangent')}") == 1
    (forces, jac) = fused(q)
    expected_forces, expected = jax.jit(lambda q: (traced(q, "jax"), jax.jacfwd(lambda q: traced(q, "jax"))(q)))(q)
    np.testing.assert_allclose(forces, expected_forces, rtol=0, atol=1e-12 * np.max(np.abs(expected_forces)))
    _assert_columns_close(jac, expected, 1e-10)
