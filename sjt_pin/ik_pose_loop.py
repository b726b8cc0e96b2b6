"""One start of the set-point search on a single pose task in one compiled call
(``sjt_pin.kernels.search_pose``): :class:`PoseLoop`, the fast path of :mod:`sjt_pin.ik`'s
:class:`~sjt_pin.ik_search.Search`, and the joint table it needs."""

from __future__ import annotations

import math
import time

import numpy as np
import pinocchio as pin

from .kernels import CONVERGED, SetPointSearch, search_pose
from .tasks import PoseTask


class PoseLoop:
    """The iterations of one start on a single :class:`~sjt_pin.tasks.PoseTask` in one compiled
    call (``sjt_pin.kernels.search_pose``): per iteration, one Pinocchio call
    (``computeFrameJacobian``, LOCAL_WORLD_ALIGNED: forward kinematics, the frame's Jacobian
    and its placement ``data.oMf``), then the pose error (``log6``), the Levenberg-Marquardt
    update, the limits and ``integrate``, compiled. The rows are the pose task's rotated into
    world axes at the frame: the same search, as its rows' weights are equal within the linear
    and within the angular block. For the robots whose joints all have one coordinate or a
    (cos, sin) pair, and no user limits (see :meth:`of`)."""

    def __init__(self, robot, frame_id: int, joints: np.ndarray):
        model = robot.model
        self.data = data = model.createData()
        self.placement = placement = data.oMf[frame_id]  # views into data, kept alive here
        self.rotation, self.translation = placement.rotation, placement.translation
        # R^T: Pinocchio's view of R is column-major, its transpose the C-contiguous rows the
        # kernel reads
        self.rotation_t = self.rotation.T
        self.trial = np.zeros(model.nq)
        self.arguments = (model, data, self.trial, frame_id, pin.LOCAL_WORLD_ALIGNED)
        self.joints = joints
        self.e = np.zeros(6)
        self.call: tuple = ()

    @classmethod
    def of(cls, robot, stack) -> PoseLoop | None:
        """The loop for ``stack``, or ``None`` when it takes the general path: not one pose
        task, rows weighted unequally within a block, or a joint other than a revolute,
        prismatic or continuous one (a floating base), or a mimic joint on the frame's chain."""
        task = stack.task
        w = stack.sqrt_weight
        if not (stack.single and type(task) is PoseTask and np.all(w[:3] == w[0])
                and np.all(w[3:] == w[3])):
            return None
        joints = joint_table(robot.model)
        model = robot.model
        support = model.supports[model.frames[task.frame_id].parentJoint]
        if joints is None or any(model.joints[j].nv == 0 for j in support[1:]):
            return None  # another joint type, or a mimic joint moves the frame
        loop = cls(robot, task.frame_id, joints)
        return loop if loop.tracks(robot, task.frame_id) else None

    def tracks(self, robot, frame_id: int) -> bool:
        """Whether the placement's views follow Pinocchio's data (checked once)."""
        for q in (pin.neutral(robot.model), robot.random_configuration(np.random.default_rng(0))):
            self.trial[:] = q
            pin.computeFrameJacobian(*self.arguments)
            expected = robot.fk(q, frame_id)
            if not (np.allclose(self.rotation, expected.rotation, rtol=0.0, atol=1e-12)
                    and np.allclose(self.translation, expected.translation, rtol=0.0,
                                    atol=1e-12)):
                return False
        return True

    def aim(self, core: SetPointSearch, target: pin.SE3) -> None:
        """The kernel's arguments for the starts of one solve of the search ``core`` to
        ``target``."""
        self.call = (core, pin.computeFrameJacobian, self.arguments, self.rotation_t,
                     self.translation, target.homogeneous, self.joints, self.trial, self.e)

    def run(self, q0: np.ndarray, limit: int, deadline: float) -> tuple[bool, int]:
        """One start from ``q0`` (the search's state already reset): (converged, iterations
        used)."""
        self.trial[:] = q0
        chunk = limit if deadline == math.inf else 16  # the clock between chunks
        iterations = 0
        while iterations < limit:
            status, used = search_pose(*self.call, min(chunk, limit - iterations))
            iterations += used
            if status:
                return status == CONVERGED, iterations
            if time.perf_counter() > deadline:
                break
        return False, iterations


def joint_table(model: pin.Model) -> np.ndarray | None:
    """(3, k) int64: q index, v index and kind (0: one coordinate, q + v; 1: a continuous joint's
    (cos, sin) pair) of every joint with coordinates, or ``None`` if a joint is of another
    kind."""
    rows = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq == 0 and joint.nv == 0:  # a mimic joint: no coordinate of its own
            continue
        if joint.nq == 1 and joint.nv == 1:
            rows.append((joint.idx_q, joint.idx_v, 0))
        elif joint.nq == 2 and joint.nv == 1 and ("RUB" in joint.shortname()
                                                   or "RevoluteUnbounded" in joint.shortname()):
            rows.append((joint.idx_q, joint.idx_v, 1))
        else:
            return None
    return np.array(rows, dtype=np.int64).reshape(-1, 3).T.copy()
