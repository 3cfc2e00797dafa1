"""`benchmarks/library_compile.py` compiles the libraries `hertzchain kernel --all` builds."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import library_compile

from hertzchain import native
from hertzchain.native import build


def test_its_table_is_the_set_the_kernel_command_builds():
    table = library_compile.libraries()
    assert len(table) == len(native.library_table()) == 11
    names = {build._library_path(defines, source).name for defines, source in table.values()}
    assert names == {path.name for path in build._current_host_libraries()}
    assert table["thornton_sensors"][0] == (f"-D{build.LAW_DEFINES['thornton']}", f"-D{build.SENSOR_DEFINE}")
