"""What a command prints and returns when it refuses its input: one line naming the file or
option and the fix, and the exit codes of every command (the `--help` epilog)."""

from __future__ import annotations

import errno

EXIT_CODES = """exit status:
  0  done (fit: converged)
  2  bad input: an option, a file that cannot be read or parsed, an output folder that
     cannot be written (one line on stderr names the file or option and the fix)
  3  fit: the optimiser did not converge; diagnose, contact: a fit the result rests on did
     not converge (the reports are still written, marked so); sweep: some runs are not
     finite (their rows have result_finite = 0)
  4  fit --posterior --strict: the posterior's diagnostics fail; kernel: a library could not
     be built (the compiler's message is printed; those runs use the JAX kernel)"""


def input_error_text(error: Exception) -> str:
    """One line for an input error: the library's message, or for an error of the file system
    (`OSError`) the file, what went wrong and what to do."""
    if isinstance(error, UnicodeDecodeError):
        return (f"a file is not UTF-8 text (byte {error.object[error.start:error.start + 1]!r} at "
                f"position {error.start}); save it as UTF-8.")
    if not isinstance(error, OSError) or error.errno is None:
        return " ".join(str(error).split("\n"))
    where = error.filename if error.filename is not None else "a file"
    fixes = {errno.EACCES: "check its permissions (an output folder: choose another --out)",
             errno.EPERM: "check its permissions (an output folder: choose another --out)",
             errno.EROFS: "the file system is read-only: choose another --out",
             errno.ENOSPC: "the disk is full: free space or choose another --out",
             errno.ENOENT: "check the path",
             errno.ENOTDIR: "a part of the path is a file, not a folder: check the path",
             errno.EISDIR: "it is a folder: give a file",
             errno.EEXIST: "remove it or choose another name"}
    fix = fixes.get(error.errno, "check the path")
    return f"{where}: {error.strerror or error}; {fix}."
