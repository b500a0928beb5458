"""Fixtures made in code for the grasp tests: a test hand, box parts, a table and a robot double."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.interfaces import IKResult, Obstacle, PartModel, Robot
from asmteach.core.models import HandSpec, PartSpec, Primitive, SolidSpec
from asmteach.core.parts import build_part
from asmteach.core.robot import PlanningScene


def make_hand() -> HandSpec:
    """0-85 mm stroke; fingers 10 x 20 x 45 mm; pads 20 x 30 mm on the TCP; palm behind the fingers."""
    return HandSpec(
        name="test_2f",
        max_width=0.085,
        finger_size=[0.010, 0.020, 0.045],
        pad_size=(0.020, 0.030),
        # finger tip at z = +0.015 (pad centred on the TCP), so the palm face is at z = -0.030
        palm_center=[0.0, 0.0, -0.050],
        palm_size=[0.040, 0.100, 0.040],
    )


def box_part(size: Sequence[float], name: str = "box", subtract: Sequence[Primitive] = ()) -> PartModel:
    """A box part (metres) with its bottom face on z = 0, optionally with primitives cut out."""
    add = [Primitive(shape="box", size=list(size), pose={"xyz": [0, 0, size[2] / 2]})]
    return build_part(PartSpec(name=name, solid=SolidSpec(add=add, subtract=list(subtract))))


class WristScene(PlanningScene):
    """The point arm's scene: its wrist sphere (radius 0.03 m) checked against the obstacles' bounding boxes."""

    def __init__(self, robot: PointArm, configuration: dict[str, np.ndarray]) -> None:
        super().__init__(configuration)
        self.robot = robot

    def _hits(self, q: np.ndarray) -> list[tuple[str, str]]:
        c = self.robot.wrist(q)
        out = []
        for ob in self.obstacles:
            m = ob.mesh.copy()
            m.apply_transform(ob.T_world)
            lo, hi = m.bounds
            if np.linalg.norm(c - np.clip(c, lo, hi)) < 0.03:
                out.append(("wrist", ob.name))
        return out

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        return np.array([bool(self._hits(q)) for q in np.atleast_2d(qs)])

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        return np.full(len(np.atleast_2d(qs)), min(1.0, upto))

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        return [self._hits(q) for q in np.atleast_2d(qs)]


class PointArm(Robot):
    """A robot double: the TCP can reach any pose within ``reach`` of its base, approaching not from below.

    Its configuration is ``(x, y, z, rx, ry, rz)`` (TCP position and rotation
    vector); its only link besides the hand is a wrist sphere of radius 0.03 m
    0.12 m behind the TCP, checked against the obstacles' bounding boxes.
    """

    def __init__(self, hand: HandSpec, base: Sequence[float] = (0.0, 0.0, 0.3), reach: float = 0.6) -> None:
        super().__init__({})
        self._hand = hand
        self.base = np.asarray(base, dtype=float)
        self.reach = reach
        self.scene = WristScene(self, {"left": self.home("left")})

    @property
    def arms(self) -> list[str]:
        return ["left"]

    @property
    def hand(self) -> HandSpec:
        return self._hand

    def joint_names(self, arm: str) -> list[str]:
        return ["x", "y", "z", "rx", "ry", "rz"]

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        return np.full(6, -10.0), np.full(6, 10.0)

    def home(self, arm: str) -> np.ndarray:
        return np.zeros(6)

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        return geometry.from_rotvec(q[3:], q[:3])

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        if np.linalg.norm(T_world_tcp[:3, 3] - self.base) > self.reach:
            return IKResult(False, None, reason="out of reach")
        if T_world_tcp[2, 2] > 0.3:  # approach pointing up: the wrist cannot turn that far
            return IKResult(False, None, reason="wrist limit")
        from scipy.spatial.transform import Rotation

        q = np.concatenate([T_world_tcp[:3, 3], Rotation.from_matrix(T_world_tcp[:3, :3]).as_rotvec()])
        return IKResult(True, q, 0.0, 0.0)

    def wrist(self, q: np.ndarray) -> np.ndarray:
        T = self.fk("left", q)
        return T[:3, 3] - 0.12 * T[:3, 2]


def table_obstacle() -> Obstacle:
    """A 1 x 1 m table, 2 cm thick, its top at z = 0."""
    m = trimesh.creation.box(extents=[1.0, 1.0, 0.02])
    return Obstacle("table", m, geometry.from_rotation(np.eye(3), [0.0, 0.0, -0.01]))


@pytest.fixture(scope="session")
def hand() -> HandSpec:
    """The test hand (see :func:`make_hand`)."""
    return make_hand()


@pytest.fixture(scope="session")
def make_box():
    """Factory of box parts: ``make_box(size, name=..., subtract=...)``."""
    return box_part


@pytest.fixture(scope="session")
def block(hand: HandSpec) -> PartModel:
    """A 40 x 60 x 30 mm block: graspable across each of its three widths."""
    return box_part([0.040, 0.060, 0.030], name="block")


@pytest.fixture
def table() -> Obstacle:
    return table_obstacle()


@pytest.fixture
def point_arm(hand: HandSpec) -> PointArm:
    return PointArm(hand)
