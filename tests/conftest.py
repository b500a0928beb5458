"""Fixtures shared by every test folder: the real data of ``<repo>/../shared/data`` (read in place, never copied).

Moved here from ``tests/plugins/detectors/aruco/conftest.py`` so the robot tests (the vendor's Nextage URDF)
and the ArUco tests (real photos) use one skip/fail rule.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    import numpy as np
    import trimesh

    from asmteach.core.interfaces import PartModel
    from asmteach.core.perception.second_view import DepthView

# tests/conftest.py -> parents[1] is the repository root; the data sit beside it.
REAL_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


def require_real_data(folder: Path, need: str = "real") -> Path:
    """``folder`` resolved if it holds ``need`` (a sub-folder); otherwise skip the test, or fail it when ``CI``
    is set (CI clones ``shared/`` beside the repository: a missing folder there is a broken setup, not a reason)."""
    if not (folder / need).is_dir():
        reason = f"real sensor data not found at {(folder / need).resolve()} (clone shared/ beside the repository)"
        if os.environ.get("CI"):
            pytest.fail(reason + "; CI must provide it")
        pytest.skip(reason)
    return folder.resolve()


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The shared real-data folder with its ``real/`` photos and scans (see :func:`require_real_data`)."""
    return require_real_data(REAL_DATA)


@pytest.fixture(scope="session")
def vendor_robots() -> Path:
    """``../shared/data/robots``: the vendor's robot descriptions (the same skip/fail rule)."""
    return require_real_data(REAL_DATA, "robots/nextage_open") / "robots"


@pytest.fixture(scope="session")
def d_peg_mesh() -> trimesh.Trimesh:
    """A round peg, radius 15 mm and 60 mm long along y, with a flat at x = 9 mm: the hull of the D outline
    (metres, part frame at the axis' middle). Read-only: shared by the tests that judge its rival turns."""
    import numpy as np
    import trimesh

    r, flat, length = 0.015, 0.009, 0.06
    a = np.linspace(0.0, 2.0 * np.pi, 96, endpoint=False)
    ring = np.c_[r * np.cos(a), r * np.sin(a)]
    ring = ring[ring[:, 0] <= flat]
    half = np.sqrt(r * r - flat * flat)
    outline = np.r_[ring, [[flat, -half], [flat, half]]]
    pts = np.r_[
        np.c_[outline[:, 0], np.full(len(outline), -length / 2), outline[:, 1]],
        np.c_[outline[:, 0], np.full(len(outline), length / 2), outline[:, 1]],
    ]
    return trimesh.convex.convex_hull(pts)


@pytest.fixture(scope="session")
def d_peg_poses(d_peg_mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """``(T_true, T_rival)`` (world, metres; read-only): the D peg lying on its round side at (0.45, 0) with its
    flat facing +x (away from a Kinect on the robot's side of the table), and that pose turned 20 deg about the
    peg's axis through its centre of mass (the flat down, out of that Kinect's sight)."""
    import numpy as np

    from asmteach.core import geometry

    T = np.eye(4)
    T[:3, 3] = [0.45, 0.0, -float(d_peg_mesh.bounds[0, 2])]
    com = np.asarray(d_peg_mesh.center_mass, float)
    R = geometry.from_rotvec([0.0, np.radians(20.0), 0.0])[:3, :3]
    rival = T @ geometry.from_rotation(R, com - R @ com)
    for M in (T, rival):
        M.flags.writeable = False
    return T, rival


@pytest.fixture(scope="session")
def d_peg_part(d_peg_mesh: trimesh.Trimesh) -> PartModel:
    """The D peg as a part model (0.1 kg, centre of mass the mesh's); read-only."""
    import numpy as np

    from asmteach.core.interfaces import PartModel
    from asmteach.core.models import PartSpec

    return PartModel(PartSpec(name="d_peg", mesh="d_peg.stl"), d_peg_mesh, 0.1, np.asarray(d_peg_mesh.center_mass))


@pytest.fixture(scope="session")
def table_kinect_view() -> Callable[[trimesh.Trimesh, np.ndarray, np.ndarray, int], DepthView]:
    """``view(mesh, T_world_part, eye, seed)``: one Kinect frame (noise on, seeded) of ``mesh`` on a 0.8 x 1.2 m
    table whose top is z = 0, from the camera centre ``eye`` (world, metres) looking at the work centre
    (0.45, 0, 0); the frame's points and the camera centre as a :class:`DepthView`."""
    import numpy as np
    import trimesh

    from asmteach.core import geometry
    from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
    from asmteach.core.perception.second_view import DepthView

    table = trimesh.creation.box(extents=[0.8, 1.2, 0.02])
    T_table = geometry.from_rotation(np.eye(3), [0.45, 0.0, -0.01])

    def view(mesh: trimesh.Trimesh, T: np.ndarray, eye: np.ndarray, seed: int) -> DepthView:
        cam = DepthCamera(KinectSettings(), seed=seed)
        frame = cam.render([(table, T_table), (mesh, T)], look_at(eye, np.array([0.45, 0.0, 0.0])))
        return DepthView(frame.points_world, eye)

    return view
