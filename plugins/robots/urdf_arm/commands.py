"""CLI commands of the URDF arm: ``asmteach robot-check``.

``asmteach robot-check URDF [--joints J1,J2,... --tcp LINK]`` parses a URDF
(errors name the file and the element), loads it in pinocchio and PyBullet,
lists its joints with limits and, when an arm is named, compares the two
libraries' forward kinematics on random configurations and checks IK
round trips. Exit 0 when everything agrees, 1 when the libraries disagree,
2 for bad input.
"""

from __future__ import annotations

import argparse

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl

__all__ = ["asmteach_add_commands", "robot_check"]


def robot_check(urdf: str, joints: list[str] | None, tcp: str | None, samples: int = 50, seed: int = 0) -> int:
    """Check a URDF; print a report; return the exit code."""
    from asmteach.core.arm.kinematics import Kinematics
    from asmteach.core.arm.sim import PyBulletWorld
    from asmteach.plugins.robots.urdf_arm.robot import resolve_urdf

    path = resolve_urdf(urdf)
    arms = {"arm": (joints, tcp)} if joints and tcp else {}
    if bool(joints) != bool(tcp):
        raise UserError("give both --joints and --tcp to check an arm (or neither)")
    kin = Kinematics(path, arms, np.eye(4))
    info = kin.info
    print(f"{path}: robot {info.name!r}, {len(info.links)} links, {len(info.joints)} joints, root {info.root!r}")
    m = kin.model
    for j in range(1, m.njoints):
        q = m.joints[j].idx_q
        print(
            f"  {m.names[j]:<28s} [{m.lowerPositionLimit[q]: .4f}, {m.upperPositionLimit[q]: .4f}] rad, "
            f"speed {m.velocityLimit[q]:.3f}"
        )
    if not arms:
        return 0
    sim = PyBulletWorld(path, np.eye(4))
    try:
        c = kin.chain("arm")
        rng = np.random.default_rng(seed)
        worst = 0.0
        ik_ok = 0
        for _ in range(samples):
            q = rng.uniform(c.lower, c.upper)
            sim.set_joints(joints, q)
            T_pin = kin.fk("arm", q)
            T_pb = sim.link_pose(tcp)
            worst = max(worst, float(np.linalg.norm(T_pin[:3, 3] - T_pb[:3, 3])))
            ik_ok += kin.ik("arm", T_pin, rng=rng, flipped=False).success
    finally:
        sim.close()
    print(f"FK pinocchio vs PyBullet over {samples} random configurations: max TCP difference {worst:.2e} m")
    print(f"IK round trips: {ik_ok}/{samples} solved")
    return 0 if worst < 1e-6 else 1


def _cmd_robot_check(args: argparse.Namespace) -> int:
    joints = [j.strip() for j in args.joints.split(",")] if args.joints else None
    return robot_check(args.urdf, joints, args.tcp, samples=args.samples, seed=args.seed)


@hookimpl
def asmteach_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Add ``robot-check``."""
    p = subparsers.add_parser("robot-check", help="check a URDF: parse, load in pinocchio and PyBullet, compare FK")
    p.add_argument("urdf", help="URDF file, pybullet_data:<relative path> or example-robot-data:<relative path>")
    p.add_argument("--joints", default=None, help="comma-separated arm joints, base to tip")
    p.add_argument("--tcp", default=None, help="TCP link of the arm")
    p.add_argument("--samples", type=int, default=50, help="random configurations to compare")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_robot_check)
