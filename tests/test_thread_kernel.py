"""The one-thread-per-chain kernel (`chain_kernel_thread.cu`) against the JAX kernel: its
host build ("emulated", the same source with one loop over the threads) wherever a C++
compiler is, its CUDA build where JAX runs on a GPU."""

import jax
import numpy as np
import pytest
from helpers import (
    TRANSFORMS,
    assert_fit_iteration_equals_the_jax_kernels,
    assert_forces_equal_the_jax_kernels,
    assert_transform_is_one_call_equal_to_the_jax_kernel,
    ten_bead_batch,
)

import hertzchain as hc
from hertzchain import native
from hertzchain.batched import solve_batched
from hertzchain.integrate import Recording


def _backends():
    on_gpu = jax.default_backend() == "gpu"
    emulated = native.thread_unavailable_reason("emulated")
    cuda = native.thread_unavailable_reason("cuda")
    return [
        pytest.param("emulated", marks=pytest.mark.skipif(
            on_gpu or emulated is not None, reason=emulated or "JAX runs on a GPU here: the CUDA build is tested")),
        pytest.param("cuda", marks=pytest.mark.skipif(
            not on_gpu or cuda is not None, reason=cuda or "no GPU")),
    ]


@pytest.fixture(params=_backends())
def backend(request, monkeypatch):
    """Every fused kernel call of this test on the thread kernel of `request.param`."""

    def kernel_for(flags, devices, rows=None):
        if flags.full_state and flags.ledger:
            return None
        return native.FusedKernel("full" if flags.full_state else "conservative", request.param)

    monkeypatch.setattr(native, "kernel_for", kernel_for)
    return request.param


CASES = {
    "rigid_and_soft_walls": ({}, True),
    "sensors_preload": ({"sensor_beads": (3, 7), "precompression_n": 3.0}, True),
    "free_end_preload": ({"end": "free", "precompression_n": 2.0}, True),
    "viscous_friction": ({"eta_s": 2e-6, "mu": 0.19}, False),
    "sensors_preload_viscous_friction": (
        {"eta_s": 2e-6, "mu": 0.19, "sensor_beads": (3, 7), "precompression_n": 3.0}, False),
}


# the slow-marked cases' physics is also in the default ones (books: in "sensors_preload";
# free end and damping alone: in "sensors_preload_viscous_friction"; the transformations'
# folding of chains and directions is the host kernel's Python, tested in test_native.py;
# the tangents by default in `test_fit_iteration_equals_the_jax_kernels`)
_SLOW_CASES = ("rigid_and_soft_walls", "free_end_preload", "viscous_friction")
_SLOW_TRANSFORMS = tuple(TRANSFORMS)


def _marked(names, slow):
    return [pytest.param(name, marks=pytest.mark.slow) if name in slow else name for name in names]


@pytest.mark.parametrize("case", _marked(CASES, _SLOW_CASES))
def test_forces_and_maxima_agree_with_the_jax_kernel(case, backend):
    """Recorded forces (and, conservative, the largest force of every contact) of the
    thread kernel equal the JAX kernel's to round-off: the same operations in the same
    order, no fused multiply-adds (the sensors' stiff springs amplify round-off a little)."""
    kwargs, books = CASES[case]
    setup, grid = ten_bead_batch(**kwargs)
    ours, reference = assert_forces_equal_the_jax_kernels(setup, grid, books=books)
    if books:
        np.testing.assert_allclose(ours.max_force_n, reference.max_force_n, rtol=1e-12)
        np.testing.assert_allclose(ours.energy_error_j, reference.energy_error_j, rtol=0,
                                   atol=1e-11 * float(np.max(reference.initial_energy_j)))


@pytest.mark.parametrize("transform", _marked(TRANSFORMS, _SLOW_TRANSFORMS))
def test_derivatives_under_vmap_and_jacfwd_are_one_call_equal_to_the_jax_kernel(transform, backend):
    """jacfwd (five directions: damping, friction, impact speed, preload, bead modulus),
    vmap and their compositions through `record_batched` on the thread kernel: one custom
    call each (directions and mapped chains become threads), values and derivatives those
    of the JAX kernel under the same transformation to round-off."""
    # the test's chain: 10 beads and a striker, the wall's row: 12 rows
    assert_transform_is_one_call_equal_to_the_jax_kernel(
        transform, lambda t: f"hertzchain_thread_{backend}_r12_{'full' if t == 'vmap' else 'tangent'}")


def test_fit_iteration_equals_the_jax_kernels(backend, monkeypatch):
    """What a fit iteration computes (whitened residuals and their Jacobian in eta, mu, C
    and the nuisances) on the thread kernel equals the same on the JAX kernel."""
    assert_fit_iteration_equals_the_jax_kernels(monkeypatch)


def test_too_many_channels_are_refused_with_the_limit(backend):
    """A kernel run records at most 16 channels: more is refused with the limit named (17
    channels of a 12-bead chain, five contacts recorded twice: the chain length whose kernel
    the fit-iteration test builds, so that no library is built for this refusal alone)."""
    setup, _ = hc.batch_setup(hc.ChainSetup(12), striker_velocity_m_s=[0.5])
    grid = hc.choose_time_grid(setup, t_end_s=0.1e-3, sample_interval_s=2e-6)
    with pytest.raises(Exception, match="at most 16 recorded channels"):
        solve_batched(setup, grid, Recording(tuple(range(12)) + tuple(range(5))), books=False)


_FAKE_NVCC = """#!/bin/sh
if [ "$1" = --version ]; then echo "Cuda compilation tools, release 12.4"; exit 0; fi
{body}
"""
_BUILDS = {
    # the compiler fails: its first line is the reason given
    "compiler fails": (("echo 'nvcc fatal   : Unsupported gpu architecture compute_99' >&2\n"
                        "echo 'second line of the failure' >&2\nexit 1"),
                       "nvcc fatal   : Unsupported gpu architecture compute_99"),
    # the build "succeeds" but writes no shared library: loading it fails
    "library does not load": (('while [ $# -gt 0 ]; do if [ "$1" = -o ]; then echo "not a library" > "$2"; fi; '
                               "shift; done\nexit 0"),
                              "file too short"),
}


@pytest.mark.parametrize("build", list(_BUILDS))
def test_a_gpu_kernel_that_cannot_be_built_is_announced_once_and_its_runs_take_the_jax_kernel(
        build, tmp_path, monkeypatch, capsys):
    """On a GPU with a CUDA compiler whose build of the thread kernel fails (or whose library
    does not load), a simulation does not raise: the failure is said once on stderr with its
    first line, recorded in `kernel_record`, and the runs are the JAX kernel's."""
    body, first_line = _BUILDS[build]
    nvcc = tmp_path / "nvcc"
    nvcc.write_text(_FAKE_NVCC.format(body=body))
    nvcc.chmod(0o755)
    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("HERTZCHAIN_NATIVE", raising=False)
    monkeypatch.setattr(native.thread, "_nvcc", lambda: str(nvcc))
    monkeypatch.setattr(native.host, "_platforms", lambda devices: {"gpu"})
    monkeypatch.setattr(native.registry, "_FAILED", {})
    monkeypatch.setattr(native.thread, "_thread_library", native.thread._thread_library.__wrapped__)  # (uncached: tried anew)
    setup, grid = ten_bead_batch()
    runs = [solve_batched(setup, grid, Recording(contacts=(2, 5)), books=True) for _ in range(2)]
    reference = solve_batched(setup, grid, Recording(contacts=(2, 5)), books=True, kernel="jax")
    for ours in runs:
        assert ours.kernel == "jax"
        for name, force in reference.forces_n.items():
            np.testing.assert_array_equal(ours.forces_n[name], force)
        np.testing.assert_array_equal(ours.max_force_n, reference.max_force_n)
    err = capsys.readouterr().err
    said = "hertzchain: the cuda chain kernel for 11 bodies cannot be used ("
    assert err.count(said) == 1 and first_line in err.split(said)[1].splitlines()[0]
    assert "second line" not in err and "those runs take the JAX kernel instead" in err
    record = native.kernel_record()
    assert record["name"].endswith("jax")
    (library, why), = record["not_available"].items()
    assert library.startswith("chain_thread-cuda-r12-") and first_line in why
