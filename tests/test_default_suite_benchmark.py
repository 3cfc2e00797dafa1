"""`benchmarks/default_suite.py` reads the parts of a `.ci/run` log."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import default_suite


def test_reads_the_libraries_the_tests_and_the_docs_from_a_log():
    log = ("kernel libraries ready in 107 s\n....\n"
           "1076 passed, 32 skipped in 274.25s (0:04:34)\nINFO    -  Documentation built in 40.03 seconds\n")
    assert default_suite.parse_log(log) == {"kernel_libraries_s": 107.0, "passed": 1076, "failed": 0, "skipped": 32,
                                            "pytest_s": 274.25, "docs_build_s": 40.03}
    failing = default_suite.parse_log("== 3 failed, 1070 passed, 2 skipped in 300.5s ==")
    assert failing == {"kernel_libraries_s": None, "passed": 1070, "failed": 3, "skipped": 2, "pytest_s": 300.5,
                       "docs_build_s": None}
