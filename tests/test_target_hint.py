"""A position (3-vector) given where a pose is expected says which task takes positions."""

import numpy as np
import pytest

import sjt_pin as sjt


@pytest.fixture(scope="module")
def ur5():
    return sjt.Robot.from_example("ur5")


@pytest.mark.parametrize("task", [sjt.PoseTask(), sjt.OrientationTask()],
                         ids=lambda task: type(task).__name__)
def test_a_3_vector_target_of_a_pose_task_suggests_position_task(ur5, task):
    solver = sjt.SJTSolver(ur5, task=task)
    for call in (lambda: solver.step(ur5.q0, np.array([0.3, 0.2, 0.4])),
                 lambda: solver.solve([0.3, 0.2, 0.4], ur5.q0)):
        with pytest.raises(ValueError, match=r"got a 3-vector .*PositionTask\(\)"):
            call()


def test_the_suggested_task_takes_that_target(ur5):
    q = sjt.SJTSolver(ur5, task=sjt.PositionTask()).step(ur5.q0, np.array([0.3, 0.2, 0.4]))
    assert q.shape == ur5.q0.shape and np.all(np.isfinite(q))
