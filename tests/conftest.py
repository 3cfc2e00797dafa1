import os
import sys
import time

# The suite checks numbers, not speed (`benchmarks/` does): XLA compiles its programs at
# backend optimisation level 0. About half of the suite's time is XLA compiling programs that
# then run for milliseconds; level 0 compiles them faster (4 of its heaviest modules, 2 cores:
# 132 -> 108 s). The programs compute the same functions, but not always rounded alike: at
# level 0 two JAX programs of the same physics (a run with the energy books and one without)
# differed by 5e-12 relative where at the default level they are identical to the bit. So a
# test that asserts two JAX programs bit-identical runs itself again in a process at the
# default level (`helpers.rerun_at_the_default_xla_level`); comparisons to a tolerance hold at
# either level. Set before JAX starts its backend; a user's own XLA_FLAGS are kept, level
# included, and DEFAULT_LEVEL_VARIABLE=1 keeps the default level.
DEFAULT_LEVEL_VARIABLE = "HERTZCHAIN_TEST_XLA_DEFAULT_LEVEL"
if (os.environ.get(DEFAULT_LEVEL_VARIABLE) != "1"
        and "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", "")):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0").strip()

import jax
import pytest

import hertzchain

jax.config.update("jax_enable_x64", True)

# The fitting commands keep compiled programs in the user's cache (fitting.compilation_cache);
# commands called in-process here would switch that on for the rest of the session and write
# hundreds of the suite's programs there. tests/test_compilation_cache.py tests the switch.
os.environ.setdefault("HERTZCHAIN_NO_COMPILE_CACHE", "1")


# The kernel libraries that only slow tests run (`-m slow`: tests/test_native_laws.py,
# tests/test_compliant_sensor.py): the default suite compiles them through the compiler's
# front end only (`native.check_libraries`, ~2 s each instead of ~20 s of compiler CPU).
# (Measured: a default run that recorded every library it loaded loaded the other eight.)
SLOW_SUITE_LIBRARIES = ("power_law compliant sensors", "thornton compliant sensors", "jackson_green compliant sensors")


def pytest_configure(config):
    """Before a parallel run's workers start, build every kernel library not yet in the cache
    that its tests run, several at once (as `hertzchain kernel --all`): on a cold cache the
    workers would otherwise each wait for the libraries their tests need, one compiler
    running while the other core idles. Targeted runs (`-n 0`) build only what their tests
    use. Where a compiler is, a library that cannot be built ends the run here, naming it:
    every library is checked, those only the slow suite runs (`SLOW_SUITE_LIBRARIES`, built
    in full when slow tests are selected) by compiling them without generating code."""
    from hertzchain import native

    if (hasattr(config, "workerinput") or config.getoption("numprocesses", None) in (None, 0)
            or os.environ.get("HERTZCHAIN_NATIVE", "1") == "0" or native.build._cxx() is None):
        return
    began = time.perf_counter()
    names = tuple(native.library_table())
    checked = () if "not slow" not in (config.getoption("markexpr", "") or "") else SLOW_SUITE_LIBRARIES
    built = tuple(name for name in names if name not in checked)
    failed = [(name, why) for name, _, _, why in native.build_libraries(built) if why]
    failed += [(name, why) for name, why in native.check_libraries(checked) if why]
    if failed:
        pytest.exit("kernel libraries that could not be built: "
                    + "; ".join(f"{name}: {why.splitlines()[0]}" for name, why in failed), returncode=1)
    print(f"kernel libraries ready in {time.perf_counter() - began:.0f} s", file=sys.stderr)


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
