"""The simulated cell's depth cameras: the second one sees the part from beside the table, the first is unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.models import PartSpec, Primitive, SolidSpec, TablePlane
from asmteach.core.parts import build_part


def _world(settings: dict) -> object:
    from asmteach.plugins.robots.nextage.robot import NextagePyBullet

    robot = NextagePyBullet(settings)
    box = build_part(PartSpec(name="box", solid=SolidSpec(add=[Primitive(shape="box", size=[0.06] * 3)])))
    T_box = np.eye(4)
    T_box[:3, 3] = [0.45, 0.0, 0.03]
    robot.reset_world(TablePlane(height=0.0), {"box": (box, T_box)})
    return robot


@pytest.mark.slow
def test_the_second_camera_sees_the_box_from_beside_and_the_first_is_unchanged() -> None:
    side = {"eye": [0.45, -0.8, 0.6], "target": [0.45, 0.0, 0.0]}
    with _world({"second_camera": side}) as two, _world({}) as one:
        assert two.depth_views() == 2 and one.depth_views() == 1
        assert np.allclose(two.camera_pose(1)[:3, 3], [0.45, -0.8, 0.6])
        _, seen = two.sense_depth(view=1)
        near_box = np.linalg.norm(seen[:, :2] - [0.45, 0.0], axis=1) < 0.045
        # beside the table it sees the box's -y face, which the first camera (across the table) does not
        face = near_box & (np.abs(seen[:, 1] + 0.03) < 0.004) & (seen[:, 2] > 0.005)
        assert face.sum() > 200
        depth_two, cloud_two = two.sense_depth()
        depth_one, cloud_one = one.sense_depth()
        assert np.array_equal(cloud_two, cloud_one) and np.array_equal(depth_two, depth_one, equal_nan=True)
        with pytest.raises(UserError, match="depth camera 1 is not configured"):
            one.camera_pose(1)
