"""The package's version: one declaration, `pyproject.toml`'s."""


def installed_version() -> str:
    """The version of the installed `hertzchain` distribution (its metadata), or of
    `pyproject.toml` beside the package when it runs from a checkout that is not installed."""
    from importlib import metadata

    try:
        return metadata.version("hertzchain")
    except metadata.PackageNotFoundError:
        import tomllib
        from pathlib import Path

        pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
        if pyproject.is_file():
            return tomllib.loads(pyproject.read_text())["project"]["version"]
        return "unknown"
