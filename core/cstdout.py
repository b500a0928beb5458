"""Silence what C libraries print on the process's stdout (file descriptor 1).

PyBullet's V-HACD and some solvers write progress straight to fd 1, below
Python's ``sys.stdout``, which would garble the console and any piped output.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

__all__ = ["silenced_c_stdout"]


@contextlib.contextmanager
def silenced_c_stdout() -> Iterator[None]:
    """Redirect fd 1 to ``/dev/null`` inside the block (Python's buffered output is flushed first)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
