"""Load libusb into the process before the first ``import open3d``.

open3d's wheel links ``libusb-1.0.so.0``, which a bare machine lacks; the
``libusb-package`` wheel ships it. Loading it with ``RTLD_GLOBAL`` first lets
a pip-only install import open3d. Imported by :mod:`asmteach.core`, so any
``import asmteach.<anything>`` does it.
"""

from __future__ import annotations

import ctypes

try:
    import libusb_package

    _path = libusb_package.get_library_path()
    if _path is not None:
        ctypes.CDLL(str(_path), mode=ctypes.RTLD_GLOBAL)
except (ImportError, OSError):  # the system may provide libusb itself
    pass
