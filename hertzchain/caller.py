"""Where a warning is attributed: the user's line, not the library's.

`warnings.warn(..., stacklevel=n)` names the frame n levels up, which is right only for a
fixed call depth. Calls that reach a warning through `equinox`'s module machinery or through
`jax` transformations have no fixed depth, and a `DeprecationWarning` attributed to a library
file is hidden by Python's default filters. `user_stacklevel` counts the frames instead.
"""

from __future__ import annotations

import os
import sys

# The packages whose frames are never the user's line.
LIBRARY_PACKAGES = ("hertzchain", "fitting", "equinox", "jax")


def user_stacklevel() -> int:
    """The `stacklevel` that makes a `warnings.warn` in the function calling this one name
    the first frame outside `LIBRARY_PACKAGES` (the user's script or prompt); 2 (that
    function's caller) where every frame is a library's."""
    roots = tuple(os.path.dirname(sys.modules[name].__file__) + os.sep for name in LIBRARY_PACKAGES
                  if getattr(sys.modules.get(name), "__file__", None))
    frame, level = sys._getframe(1), 1
    while frame is not None:
        filename = frame.f_code.co_filename
        if not filename.startswith(roots) and not filename.startswith("<frozen"):
            return level
        frame, level = frame.f_back, level + 1
    return 2
