"""Module paths that moved stay importable for one release, as the module at the new path,
with a `DeprecationWarning` naming it (`hertzchain._moved`)."""

import importlib
import importlib.machinery
import sys

import pytest

from hertzchain._moved import MOVED


@pytest.mark.parametrize("old_name", sorted(MOVED))
def test_an_old_path_is_the_module_at_its_new_path_with_a_warning(old_name):
    new_name = MOVED[old_name]
    sys.modules.pop(old_name, None)
    with pytest.warns(DeprecationWarning, match=f"`{old_name}` moved to `{new_name}`") as record:
        __import__(old_name)  # an import statement's call: no frame between it and this line
    assert sys.modules[old_name] is importlib.import_module(new_name)
    # attributed to the line that imported the old path, not to the import machinery
    assert [w.filename for w in record if str(w.message).startswith(f"`{old_name}` moved")] == [__file__]


def test_no_file_is_left_at_an_old_path():
    for old_name in MOVED:
        parent_name, _, _ = old_name.rpartition(".")
        if parent_name in MOVED:
            continue  # below a package that moved: its modules are found at the new path
        parent = importlib.import_module(parent_name)
        assert importlib.machinery.PathFinder.find_spec(old_name, parent.__path__) is None, old_name


def test_below_a_package_that_moved_only_the_moved_modules_are_found():
    importlib.import_module("hertzchain.cli.errors")
    with pytest.raises(ModuleNotFoundError, match="fitting.cli.errors"):
        importlib.import_module("fitting.cli.errors")


def test_the_exit_statuses_keep_their_old_home():
    from fitting.cli import EXIT_INPUT_ERROR, EXIT_NOT_CONVERGED, exit_codes_epilog

    assert (EXIT_INPUT_ERROR, EXIT_NOT_CONVERGED) == (2, 3)
    assert exit_codes_epilog("x").startswith("exit status: 0 done; 2 bad input")


def test_the_packages_import_no_old_path_themselves():
    """Every module of both packages, imported in a fresh process with the old paths'
    warning an error: the code itself uses only the new paths."""
    import subprocess

    code = ("import importlib, pkgutil, hertzchain, fitting\n"
            "for package in (hertzchain, fitting):\n"
            "    for module in pkgutil.walk_packages(package.__path__, package.__name__ + '.'):\n"
            "        if not module.name.endswith('__main__'):\n"
            "            importlib.import_module(module.name)\n")
    run = subprocess.run([sys.executable, "-W", "error::DeprecationWarning", "-c", code], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]


def test_the_driven_sweep_fit_keeps_its_former_names_with_a_warning():
    """`fitting.driven` was the sweep fit's module: its names are forwarded to
    `fitting.driven.lockin_fit` (the same objects), each with a warning naming the new path."""
    import fitting.driven
    from fitting.driven import lockin_fit

    with pytest.warns(DeprecationWarning, match=r"`fitting.driven.fit_driven` moved to `fitting.driven.lockin_fit"):
        assert fitting.driven.fit_driven is lockin_fit.fit_driven
    with pytest.warns(DeprecationWarning):
        from fitting.driven import NOMINAL_SCALE
    assert NOMINAL_SCALE == lockin_fit.NOMINAL_SCALE
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        fitting.driven.no_such_name  # noqa: B018
