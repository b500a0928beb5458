"""Batched per-configuration callables and the inverse-clearance cost map built on them."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.trajectory.batch import batch_of, batched, inverse_clearance_cost


def test_batched_answers_one_and_many_and_batch_of_falls_back_to_a_loop() -> None:
    fn = batched(lambda q: float(q.sum()), lambda qs: qs.sum(axis=1))
    qs = np.array([[1.0, 2.0], [3.0, -4.0]])
    assert fn(qs[0]) == 3.0 and np.allclose(fn.batch(qs), [3.0, -1.0])
    assert batch_of(fn) == fn.batch
    assert np.allclose(batch_of(lambda q: float(q.sum()))(qs), [3.0, -1.0])


def test_inverse_clearance_cost_floor_cap_and_batch() -> None:
    clearance = batched(lambda q: float(q[0]), lambda qs: qs[:, 0])
    cost = inverse_clearance_cost(clearance, floor=0.01, cap=0.5)
    qs = np.array([[-1.0], [0.0], [0.005], [0.1], [0.5], [3.0]])
    expected = np.array([100.0, 100.0, 100.0, 10.0, 2.0, 2.0])
    assert np.allclose([cost(q) for q in qs], expected)
    assert np.allclose(cost.batch(qs), expected)
    plain = inverse_clearance_cost(lambda q: float(q[0]))
    assert not hasattr(plain, "batch") and plain(np.array([0.25])) == pytest.approx(4.0)
    with pytest.raises(ValueError, match="floor < cap"):
        inverse_clearance_cost(clearance, floor=0.5, cap=0.1)
