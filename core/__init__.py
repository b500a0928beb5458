"""asmteach core: contracts, registry, hooks, configs and the CLI. It imports no plugin."""

from asmteach.core import _preload  # noqa: F401  (must run before anything imports open3d)
