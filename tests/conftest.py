import os

import jax
import pytest

import hertzchain

jax.config.update("jax_enable_x64", True)

# The fitting commands keep compiled programs in the user's cache (fitting.compilation_cache);
# commands called in-process here would switch that on for the rest of the session and write
# hundreds of the suite's programs there. tests/test_compilation_cache.py tests the switch.
os.environ.setdefault("HERTZCHAIN_NO_COMPILE_CACHE", "1")


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's compiled programs after each test module. One process running the whole suite
    compiles thousands of programs; kept alive together, a compilation late in the run crashed
    inside XLA (a segfault or an abort, three times at the same point of the suite, never with
    the modules run in two halves)."""
    yield
    jax.clear_caches()


@pytest.fixture(scope="session")
def paper_setup():
    """The paper's chain: 21 steel beads, R = 13 mm, identical striker at 0.3 m/s, steel wall."""
    return hertzchain.ChainSetup()
