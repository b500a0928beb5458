"""Why a planning query failed, as a kind callers branch on (never by parsing a reason string).

A planner that fails returns one of these kinds in its structured result
(:attr:`asmteach.core.interfaces.MotionResult.kind`) next to a readable
``reason`` for people; code that reacts to the failure (the regrasp planner
banning a graph node when the goal configuration itself is in collision,
counting wall-clock cuts) reads the kind.
"""

from __future__ import annotations

import enum

__all__ = ["FailureKind"]


class FailureKind(enum.StrEnum):
    """Why a joint-space motion query failed; the value starts the readable reason."""

    START_OUT_OF_BOUNDS = "start out of joint limits"
    GOAL_OUT_OF_BOUNDS = "goal out of joint limits"
    START_INVALID = "start in collision"
    GOAL_INVALID = "goal in collision"
    TIMEOUT = "timeout"
    ITERATIONS = "iteration limit"
    NO_SOLUTION = "no solution"
