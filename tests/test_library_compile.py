"""`benchmarks/library_compile.py` compiles the libraries `hertzchain kernel --all` builds."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import library_compile
import pytest
from helpers import NEEDS_A_COMPILER

from hertzchain import native
from hertzchain.native import build


def test_it_compiles_every_library_the_kernel_command_builds():
    """Its table is `hertzchain kernel --all`'s: the eleven libraries whose files the cache
    keeps (`build._current_host_libraries`, which prunes every other)."""
    table = library_compile.libraries()
    assert len(table) == 11
    names = {build._library_path(defines, source).name for defines, source in table.values()}
    assert names == {path.name for path in build._current_host_libraries()}
    assert table["thornton compliant sensors"][0] == ("-DHC_THORNTON_LIBRARY", "-DHC_SENSOR_LIBRARY")


@NEEDS_A_COMPILER
def test_front_end_check_passes_a_library_and_names_a_compile_error(tmp_path):
    """`native.check_libraries` (the default suite's check of the libraries only slow tests
    run) passes a real library and refuses a source with an error, naming it, writing nothing."""
    assert list(native.check_libraries(["thornton compliant sensors"])) == [("thornton compliant sensors", None)]
    broken = tmp_path / "broken_kernel.cc"
    broken.write_text("int f() { return undeclared_name; }\n")
    with pytest.raises(RuntimeError, match=r"compiling broken_kernel.cc failed: .*undeclared_name"):
        build.check_source((), broken)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken_kernel.cc"]
    with pytest.raises(ValueError, match="unknown kernel libraries"):
        list(native.check_libraries(["thornton_sensors"]))
