"""Command-line options that several commands take with one meaning: whether compiled programs
are kept between runs, and the folder a driven experiment's files are relative to."""

from __future__ import annotations

import argparse


def add_compile_cache_option(parser: argparse.ArgumentParser) -> None:
    """`--no-compile-cache` (`fitting.compilation_cache.enable_compilation_cache` reads it)."""
    parser.add_argument("--no-compile-cache", action="store_true",
                        help="do not keep compiled code between runs (default: kept in $HERTZCHAIN_CACHE/jax, "
                        "~/.cache/hertzchain/jax; also off with HERTZCHAIN_NO_COMPILE_CACHE=1)")


def add_driven_data_dir_option(parser: argparse.ArgumentParser) -> None:
    """`--data-dir`: where a driven experiment file's sweep files are."""
    parser.add_argument("--data-dir", help="driven experiments (kind = \"driven\"): the folder their sweep files "
                        "are relative to")
