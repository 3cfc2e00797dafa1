"""`hertzchain --version` prints the package's version, the one pyproject.toml declares."""

import tomllib
from pathlib import Path

import pytest

import hertzchain
from hertzchain.cli import main


def test_version_is_the_declared_one(capsys):
    declared = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"hertzchain {declared['project']['version']}"
    assert hertzchain.__version__ == declared["project"]["version"]
