"""Where :meth:`~sjt_pin.Solver.solve` restarts after a start has stalled: random configurations
within the limits (:class:`Sampler`), and, on a single pose task, first the configurations of a
seeded table whose poses are nearest the target (:class:`NearStarts`).

A start stalls in a local minimum of the error; on a 7-joint arm nearly always with a joint on
one of its limits. A random restart lands in another stall about as often as the first start
did (Panda: 64 % of them), as it is as far from the target as any configuration. A restart from
a configuration whose end-effector pose is already near the target has less far to go and fewer
minima on its way: the table's nearest samples, taken in order, succeed more often (Panda, with
the quicker stall test of :mod:`sjt_pin.ik`: restarts per pose 1.52 -> 0.93, the iterations'
p90 62 -> 24).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

#: the width of a uniform angle in [-pi, pi) (rad), as numpy's uniform computes it
_TURN = np.pi - (-np.pi)
#: configurations in the table of :class:`NearStarts`, and the seed they are drawn from (fixed:
#: every process builds the same table, so solve_many's results do not depend on where a pose
#: is solved)
TABLE_SIZE, TABLE_SEED = 2000, 0x5EED


class Sampler:
    """Random starts: limited joints uniform within their limits, unlimited revolute and
    continuous joints a random angle (about the seed's), the rest (a floating base, prismatic
    joints without limits) as in the seed."""

    def __init__(self, robot):
        model = robot.model
        lower, upper = robot.lower_limits, robot.upper_limits
        limited, turning, circle = [], [], []
        kept = 0  # coordinates kept from the seed
        for j in range(1, model.njoints):
            joint = model.joints[j]
            kind = joint.shortname()
            if joint.nq == 1 and joint.nv == 1:
                i = joint.idx_q
                if np.isfinite(lower[i]) and np.isfinite(upper[i]):
                    limited.append(i)
                elif "Revolute" in kind:
                    turning.append(i)
                else:
                    kept += 1
            elif joint.nq == 2 and joint.nv == 1:  # continuous: (cos, sin)
                circle.append(joint.idx_q)
            else:
                kept += joint.nq
        self.limited = np.array(limited, dtype=np.int64)
        self.lower, self.upper = lower[self.limited], upper[self.limited]
        self.turning = np.array(turning, dtype=np.int64)
        self.circle = np.array(circle, dtype=np.int64)
        self.span = self.upper - self.lower
        self.draws = self.limited.size + self.turning.size + self.circle.size
        #: whether every coordinate is drawn (none kept from the seed), all but unlimited
        #: revolute joints' independently of it
        self.complete = kept == 0

    def __call__(self, seed: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The numbers of ``rng.uniform(lower, upper)`` for the limited joints, then of
        ``rng.uniform(-pi, pi)`` for the others, bitwise (``low + (high - low) u`` on one draw
        of ``rng.random``: numpy's uniform checks array bounds at 10 us a call)."""
        return self.many(seed, rng, 1)[0]

    def many(self, seed: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` starts (count, nq) in one draw: the same numbers as ``count`` calls in
        turn (``rng.random`` fills its array in the order of successive calls)."""
        q = np.repeat(seed[None, :], count, axis=0)
        u = rng.random((count, self.draws))
        k, t = self.limited.size, self.limited.size + self.turning.size
        q[:, self.limited] = self.lower + self.span * u[:, :k]
        if t > k:
            q[:, self.turning] += -np.pi + _TURN * u[:, k:t]
        if self.circle.size:
            angles = -np.pi + _TURN * u[:, t:]
            q[:, self.circle], q[:, self.circle + 1] = np.cos(angles), np.sin(angles)
        return q


class NearStarts:
    """A seeded table of configurations and their frame's poses; after :meth:`aim` at a target,
    :meth:`next` gives them nearest first. The distance of a pose (R, p) to the target
    (R_t, p_t) is the task's own weighted error with the chord ``2 sin(theta / 2)`` for the
    angle theta of R^T R_t: ``w_p^2 |p - p_t|^2 + w_r^2 4 sin^2(theta / 2)`` (w_p and w_r the
    task's square-root weights of its linear and angular rows: w_r is the pose task's
    characteristic length). As ``4 sin^2(theta / 2) = 3 - R : R_t``, it is, but for a constant,
    one product of the table (size x 12) with the target's 3 x 4 matrix: about 4 us for 2,000
    poses.

    Build it with :meth:`of` (``None`` when it does not apply)."""

    def __init__(self, robot, frame_id: int, sampler: Sampler, w_p: float, w_r: float,
                 size: int, seed: int):
        model = robot.model
        data = model.createData()
        rng = np.random.default_rng(seed)
        neutral = pin.neutral(model)
        self.configurations = sampler.many(neutral, rng, size)
        self.configurations.flags.writeable = False  # next() hands out views
        frames = np.empty((size, 3, 4))
        for i, q in enumerate(self.configurations):
            pin.forwardKinematics(model, data, q)
            frames[i] = pin.updateFramePlacement(model, data, frame_id).homogeneous[:3]
        positions = frames[:, :, 3]
        # distance - constant = N + F . vec(H_t[:3]): F's rotation entries -w_r^2 R, its
        # translation column -2 w_p^2 p; N = w_p^2 |p|^2
        table = -w_r**2 * frames
        table[:, :, 3] = -2.0 * w_p**2 * positions
        self.table = table.reshape(size, 12)
        self.offset = w_p**2 * np.sum(positions**2, axis=1)
        self.distance = np.full(size, math.inf)

    @classmethod
    def of(cls, robot, stack, sampler: Sampler) -> NearStarts | None:
        """The table for a stack of one pose task whose rows' weights are equal within the
        linear and within the angular block, on a robot whose every coordinate the sampler
        draws; otherwise ``None``."""
        from .tasks import PoseTask

        task, w = stack.task, stack.sqrt_weight
        if not (stack.single and type(task) is PoseTask and sampler.complete
                and np.all(w[:3] == w[0]) and np.all(w[3:] == w[3])):
            return None
        return cls(robot, task.frame_id, sampler, float(w[0]), float(w[3]), TABLE_SIZE,
                   TABLE_SEED)

    def aim(self, target: np.ndarray) -> None:
        """Rank the table by its distance to ``target`` (4 x 4 homogeneous matrix)."""
        np.matmul(self.table, target[:3].ravel(), out=self.distance)
        self.distance += self.offset

    def next(self) -> np.ndarray:
        """The nearest configuration not yet given since :meth:`aim` (a read-only view; the
        compiled search takes them in the same order, ``search_pose`` with the table)."""
        i = int(self.distance.argmin())
        self.distance[i] = math.inf
        return self.configurations[i]
