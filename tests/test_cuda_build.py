"""The one-thread-per-chain kernel's CUDA build (`chain_kernel_thread.cu`, with the law header
`chain_laws.h` it shares with the host kernels) compiles wherever nvcc is, GPU or not."""

import subprocess

import pytest

from hertzchain import native

# A GPU architecture named outright: `native.NVCC_FLAGS` build for this machine's GPU
# ("-arch=native"), and the machine that checks the source may have none.
ARCHITECTURE = "-arch=sm_80"


@pytest.mark.slow  # about a minute of nvcc on 2 cores
@pytest.mark.skipif(native.thread._nvcc() is None, reason="no CUDA compiler (nvcc)")
def test_the_cuda_kernel_compiles(tmp_path):
    """nvcc builds the CUDA kernel for a chain of 10 bodies with `native`'s own command (the
    architecture named, see ARCHITECTURE) into a library that holds the three handlers; a
    compile error fails the test with nvcc's message."""
    output = tmp_path / "chain_thread_cuda.so"
    command = [ARCHITECTURE if arg == "-arch=native" else arg for arg in native.thread._thread_build_command("cuda", 11, output)]
    assert ARCHITECTURE in command
    proc = subprocess.run(command, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-4000:]
    library = output.read_bytes()
    for symbol in ("HertzChainThreadForward", "HertzChainThreadFullForward", "HertzChainThreadFullTangent"):
        assert symbol.encode() in library
