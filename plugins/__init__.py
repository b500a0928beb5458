"""Built-in plugins of asmteach, registered through entry points like any third-party one."""

from asmteach.core import _preload  # noqa: F401  (libusb before open3d)
