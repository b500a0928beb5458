"""Why something failed, as kinds callers branch on (never by parsing a reason string).

:class:`FailureKind`: why a motion query failed. A planner that fails returns
it in its structured result (:attr:`asmteach.core.interfaces.MotionResult.kind`)
next to a readable ``reason`` for people; code that reacts to the failure (the
regrasp planner banning a graph node when the goal configuration itself is in
collision, counting wall-clock cuts) reads the kind.

:class:`FailureCause`: why a whole run failed. The stage that fails names it
(:class:`asmteach.core.pipeline.StageFailed`), the assembly planner returns it
(:attr:`asmteach.core.interfaces.AssemblyResult.cause`), and ``report.json``
records it (``failure_cause``) beside the readable ``reason``.
"""

from __future__ import annotations

import enum

__all__ = ["FailureCause", "FailureKind"]


class FailureKind(enum.StrEnum):
    """Why a joint-space motion query failed; the value starts the readable reason."""

    START_OUT_OF_BOUNDS = "start out of joint limits"
    GOAL_OUT_OF_BOUNDS = "goal out of joint limits"
    START_INVALID = "start in collision"
    GOAL_INVALID = "goal in collision"
    TIMEOUT = "timeout"
    ITERATIONS = "iteration limit"
    NO_SOLUTION = "no solution"


class FailureCause(enum.StrEnum):
    """Why a run failed, in pipeline order; the value is what ``report.json`` and the sweeps record."""

    TEACH = "teach"
    """The demonstration could not be turned into a task (markers not seen, no insertion axis)."""
    DETECT_NOT_FOUND = "detect_not_found"
    """A part was not found in the depth view (no cluster, no hypothesis verified)."""
    DETECT_AMBIGUOUS = "detect_ambiguous"
    """The view could not tell two poses of a part apart (its detection lists the rivals, ``details["ambiguous"]``)."""
    CORRECT = "correct"
    """A part was found but the corrector could not refine its pose."""
    NO_GRASP = "no_grasp"
    """No grasp of a part: none for the hand, or none the arms can take at its start or goal pose."""
    REGRASP_GRAPH = "regrasp_graph"
    """Grasps exist at the start and the goal, but the regrasp graph holds no connected keyframe path between
    them, or the planner's time budget ran out searching it."""
    MOTION = "motion"
    """Keyframes were found but an arm motion between them could not be planned (IK, collision, timeout)."""
    EXECUTION_DROP = "execution_drop"
    """During execution a hand did not close on its part (it is not where the plan assumed)."""
    JAM = "jam"
    """Assembled outside tolerance after an insertion that did not get in: the guarded insertion stopped short
    at its force limit (depth, contact force and time in ``failure_details``), or B was pushed in the hand
    during an insertion."""
    TOPPLE = "topple"
    """Assembled outside tolerance after a part no hand held tipped over during a motion (which motion, when,
    how far it tilted: the execution trace's event)."""
    OFF_GOAL = "off_goal"
    """Assembled outside tolerance with no jam or topple: a part ended off its goal (moved by a named motion,
    pushed in the hand while placed, tilted as it was let go; else the insertion's error split into grasp,
    A's placement and taught pose)."""
    OTHER = "other"
    """Anything else: bad input met late, an internal error, a plugin's own failure without a cause."""
