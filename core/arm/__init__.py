"""The generic arm robot: any URDF arm with parallel grippers, pinocchio kinematics, fcl collision, PyBullet.

Robot plugins build on it (the Nextage, ``urdf_arm``); it depends on the core only:

- :mod:`~asmteach.core.arm.robot`: :class:`ArmRobot` (a :class:`~asmteach.core.interfaces.Robot` and
  :class:`~asmteach.core.robot.World`) and :class:`ArmSpec` (one arm as a subclass describes it);
- :mod:`~asmteach.core.arm.settings`: :class:`ArmRobotSettings` (the keys every arm robot shares) and its
  :class:`CameraMount` and :class:`WristCameraMount`;
- :mod:`~asmteach.core.arm.scene`: :class:`ArmScene`, its :class:`~asmteach.core.robot.PlanningScene`;
- :mod:`~asmteach.core.arm.kinematics`: URDF kinematics (arm chains, joint limits, FK, Jacobian, IK entry point);
- :mod:`~asmteach.core.arm.dls_ik`: the damped-least-squares IK solver and its settings;
- :mod:`~asmteach.core.arm.joint_poses`: joint poses of many configurations at once (vectorised FK);
- :mod:`~asmteach.core.arm.batch_ik`: IK of many targets at once;
- :mod:`~asmteach.core.arm.collision`: batch collision and clearance checks (:class:`CollisionChecker`);
- :mod:`~asmteach.core.arm.collision_geometry`: its collision objects (URDF links, table, obstacles, held parts);
- :mod:`~asmteach.core.arm.obb`: vectorised oriented-box overlap and gap;
- :mod:`~asmteach.core.arm.sim`: the PyBullet world (robot, table, parts, trajectory execution);
- :mod:`~asmteach.core.arm.sim_gripper`: :class:`GripperJoints` and gripping in that world;
- :mod:`~asmteach.core.arm.sim_camera`: its RGB camera images and the wrist camera a mount describes;
- :mod:`~asmteach.core.arm.insertion`: the guarded insertion (:func:`guarded_insert`), with its settings and
  outcome in :mod:`~asmteach.core.arm.insertion_records`, its sideways search in
  :mod:`~asmteach.core.arm.insertion_search` and its turns in :mod:`~asmteach.core.arm.compliance`;
- :mod:`~asmteach.core.arm.plan_check`: the independent re-check of a plan (its rules and results);
- :mod:`~asmteach.core.arm.plan_checker`: its replay in a PyBullet world (:func:`recheck_plan`);
- :mod:`~asmteach.core.arm.link_spheres`: the re-check's bounding spheres and joint reach bounds;
- :mod:`~asmteach.core.arm.urdf_check`: URDF parsing with errors that name the element.
"""
