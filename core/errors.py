"""Errors that reach the user.

Any failure caused by the user's input (a config, a mesh, a cloud, a frame
folder) is raised as :class:`UserError`. The CLI prints its one-line message
and exits with code 2; it never shows a traceback for these.
"""

from __future__ import annotations

__all__ = ["UserError"]


class UserError(Exception):
    """A problem with the user's input, explained in one line.

    The message names the cause and, where there is one, the fix, e.g.
    ``"detector.settings.voxel_size: Input should be greater than 0 (got -1)"``.
    """

    exit_code = 2

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message

    def __str__(self) -> str:
        return self.message
