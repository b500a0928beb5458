"""The two-finger parallel gripper on the Nextage wrists, as a :class:`HandSpec`.

A Robotiq 2F-85-like gripper (0-85 mm opening) replaces the stock chuck hand,
which opens only about 10 mm. Geometry (EST, product outline) is in
:data:`asmteach.plugins.robots.nextage.build_urdf.GRIPPER`.

TCP frame (the ``*ARM_TCP_Link`` of the URDF): origin midway between the finger
pads, 0.145 m from the hand mounting interface along the approach axis;
z = approach direction, out of the palm toward the object (-x of
``*ARM_JOINT5_Link``); y = jaw axis (finger 0 on -y, finger 1 on +y);
x = y cross z (+z of ``*ARM_JOINT5_Link``).

Boxes are given in the TCP frame at zero opening. The palm (gripper body) spans
z from -0.145 to -0.070. Each finger box hangs from the palm face (z = -0.070)
to the fingertip (z = +0.0175): length 0.0875 along z, 0.010 thick along y,
0.022 wide along x; its pad (0.022 x 0.035, centred on the TCP) is on the inner
face. Each finger moves by +-width/2 along y.
"""

from __future__ import annotations

import numpy as np

from asmteach.core.models import HandSpec
from asmteach.plugins.robots.nextage.build_urdf import GRIPPER

__all__ = ["nextage_hand"]


def nextage_hand(max_force: float = 40.0) -> HandSpec:
    """HandSpec of the Nextage gripper (metres, newtons)."""
    g = GRIPPER
    body_depth, body_open, body_third = g.body_size
    return HandSpec(
        name="nextage_2f85",
        max_width=g.max_opening,
        min_width=0.0,
        finger_size=np.array([g.finger_thickness, g.finger_width, g.finger_length]),
        pad_size=(g.finger_width, g.pad_length),
        palm_center=np.array([0.0, 0.0, -g.tcp_depth + 0.5 * body_depth]),
        palm_size=np.array([body_third, body_open, body_depth]),
        max_force=max_force,
    )
