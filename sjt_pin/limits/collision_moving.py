"""Moving obstacles of :class:`sjt_pin.limits.collision.CollisionLimit`: each pair's bound on
its obstacle's speed, how long a pair with a moving obstacle is watched ahead, and the rows'
bounds carried by the obstacles' velocities.

An obstacle moved with its velocity (:meth:`CollisionLimit.move`, twist
``(v, w)`` in world axes) makes each of its pairs' rows bound the relative closing speed:

    n^T (J_a(p_a) q_dot - v_b(p_b)) <= gain (d - margin) / dt,    v_b(p) = v + w x (p - o)

(``o`` the obstacle's origin; the bound of ``A q_dot <= b`` rises by ``n^T v_b(p_b)``, falls
where the obstacle comes closer). With ``u = -n^T v_b(p_b)`` the obstacle's approach speed
and ``r = sum_j |A_ij| v_j`` the fastest the arm's speed limits ``v`` let the row's point
retreat (beside acceleration limits ``a``, a joint moving toward the end of its range counts
no faster than it can still stop there, ``v_j <= sqrt(2 a_j room_j)``:
:meth:`MovingMixin._retreat_speeds`), the guarantee is:

- without acceleration limits, where ``u <= r``: the step keeps its row, so per period the
  excess ``d - margin`` shrinks by at most the fraction ``gain`` to first order in ``dt``, as
  beside a still obstacle; without the velocity the row lags the obstacle by a period and
  the pair settles about ``u dt / gain`` inside the margin;
- with acceleration limits (``a = sum_j |A_ij| a_j`` along the row, ``BRAKING_SHARE`` of it
  counted on), the row brakes the relative closing speed ``c = s + u`` (``s`` the arm's): it
  starts giving way while its excess still covers the retreat's ramp, ``h >= c tau + c^2 /
  (2 share a)``, ``tau = dt + a / j``, and eases in at what the limits allow from the arm's
  last velocity and acceleration (the obstacle's speed is not the arm's to brake); each pair
  with a moving obstacle is watched ``u (2 dt + T)`` farther out (``T`` the longest time a
  joint takes to reach its speed limit, at most 1 s, plus the jerk's ramp:
  :meth:`CollisionLimit._lookahead`); where the obstacle comes faster than the acceleration
  limits can answer but no faster than the speed limits, the acceleration and jerk limits
  yield to the row (``limit_conflicts``): the margin wins;
- where ``u > r`` no motion within the speed limits keeps the row, and yielding the
  acceleration and jerk limits would not keep it either: beside acceleration limits the row
  counts the obstacle's approach only up to ``r`` and the stage keeps it only as far as those
  limits allow (``CollisionLimit.needs`` gives the bound the margin would need); without them
  the step breaks the row by the least the stage can. Either way ``StepInfo.rows_exceeded``
  gives ``A q_dot - b`` against the bound the margin needs (m/s; times ``dt``, how much of the
  margin the step gave up).

A moving obstacle is moved every step (its velocity holds until the next :meth:`move`); given
time-stamped poses instead (``move(i, pose, time=t)``), its twist is their backward difference,
``((p - p0) / h, log3(R R0^T) / h)`` with ``h = t - t0`` (exact where the origin's velocity
and the angular velocity are constant over ``h``; else their mean over it, to first order).

A part of the CollisionLimit (a mixin it inherits from), operating on its state."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..validation import real_number
from .base import Motion
from .collision_geometry import check_pose, obstacle_twist
from .collision_state import CollisionState


class MovingMixin(CollisionState):
    """The moving obstacles of a :class:`~sjt_pin.limits.collision.CollisionLimit`."""

    def move(self, i: int, pose: pin.SE3, velocity=None, time: float | None = None) -> None:
        """Move obstacle ``i`` (its index in ``obstacles``) to ``pose`` before the next step.

        ``velocity``: the obstacle's velocity at ``pose`` (6,): the linear velocity of its
        origin (m/s) then its angular velocity (rad/s), both in world axes (Pinocchio's
        ``LOCAL_WORLD_ALIGNED`` twist; a ``pin.Motion`` is read the same way). ``time``: the
        pose's time stamp (s, increasing from one ``move`` of this obstacle to the next):
        without ``velocity``, the velocity is the backward difference from the last
        time-stamped pose (at rest on the first; a ``move`` without ``time`` starts the
        differences anew; each interval must turn the obstacle by less than pi). Neither: an
        obstacle at rest. The velocity holds until the next ``move`` (move a moving obstacle
        every step); each row of its pairs then bounds the relative normal velocity of their
        closest points (the collision guide, "Moving obstacles")."""
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"obstacle index must be an int, got {type(i).__name__}")
        if not 0 <= i < len(self._obstacle_ids):
            raise IndexError(f"obstacle {i} does not exist ({len(self._obstacle_ids)} obstacles)")
        check_pose(pose, f"pose of obstacle {i}")
        twist = obstacle_twist(velocity, f"velocity of obstacle {i}")
        stamp = self._stamps[i]
        if time is None:
            self._stamps[i] = None
        else:
            time = real_number(time, f"time of obstacle {i}", "s")
            if not math.isfinite(time) or (stamp is not None and not time > stamp[0]):
                raise ValueError(f"time of obstacle {i} must be finite and increase from one "
                                 f"move to the next (s): {time!r} after "
                                 f"{None if stamp is None else stamp[0]!r}")
            if velocity is None and stamp is not None:
                h, before = time - stamp[0], stamp[1]
                twist = np.concatenate([(pose.translation - before.translation) / h,
                                        pin.log3(pose.rotation @ before.rotation.T) / h])
                if not np.all(np.isfinite(twist)):
                    raise ValueError(f"the velocity of obstacle {i} over {h!r} s is not "
                                     f"finite: {twist}")
            self._stamps[i] = (time, pose.copy())
        g = self._obstacle_ids[i]
        changed = bool(np.any(twist != self._velocity[i]))
        self.geometry.geometryObjects[g].placement = pose
        H = self._placement[g] = pose.homogeneous
        self._center_local[g, :3] = self._centers_in[:3, g] = (H[:3, :3] @ self._box_center[g]
                                                              + H[:3, 3])
        if changed:
            self._velocity[i] = twist
            self._moving_speeds()
        self._version += 1
        self._skip = None  # (its broad phase is of the old scene)
        self._tick += 2.0  # the remembered points on the obstacle moved: forget every one

    def _moving_speeds(self) -> None:
        """Each pair's bound on its obstacle's speed (m/s) at any point of the obstacle's
        bounding sphere, ``|v| + |w| (|c| + r)`` (``c`` the sphere's centre in the obstacle's
        frame, ``r`` its radius; inf for a turning Halfspace or Plane), 0 for a pair of the
        robot's own links: ``_pair_speed``; ``_moving``: whether any is above 0."""
        if not len(self._obstacle_ids):
            self._pair_speed, self._moving = np.zeros(len(self.pairs)), False
            return
        linear = np.linalg.norm(self._velocity[:, :3], axis=1)
        turn = np.linalg.norm(self._velocity[:, 3:], axis=1)
        index = self._pair_obstacle
        mine = index >= 0
        pick = np.where(mine, index, 0)
        with np.errstate(invalid="ignore"):
            spin = np.where(turn[pick] > 0, turn[pick] * self._pair_far, 0.0)
        self._pair_speed = np.where(mine, linear[pick] + spin, 0.0).sum(axis=1)
        self._moving = bool(np.any(self._pair_speed > 0))

    @staticmethod
    def _lookahead(motion: Motion) -> float:
        """How long (s) a pair with a moving obstacle is watched ahead: the obstacle's
        travel in this time widens the pair's influence. Two periods (the obstacle may close
        a period's travel before the row sees it and another while the step runs); with
        acceleration limits also the longest time a joint takes to reach its speed limit
        (at most 1 s), and with jerk limits the longest ramp to its acceleration limit: the
        arm may need that long to match the obstacle's speed."""
        time = 2.0 * motion.dt
        accelerations = motion.acceleration_limits
        if accelerations is None:
            return time
        speeds = motion.velocity_limits
        with np.errstate(divide="ignore", invalid="ignore"):
            if speeds is not None:
                reach = speeds / accelerations
                reach = reach[np.isfinite(reach)]
                time += min(float(reach.max()), 1.0) if reach.size else 1.0
            else:
                time += 1.0
            if motion.jerk_limits is not None:
                ramp = accelerations / motion.jerk_limits
                ramp = ramp[np.isfinite(ramp)]
                time += float(ramp.max()) if ramp.size else 0.0
        return time

    def _retreat_speeds(self, motion: Motion) -> np.ndarray | None:
        """How fast each joint can move down (row 0) and up (row 1) (2, nv; rad/s or m/s):
        its speed limit, and toward a position range's end no faster than it can still stop
        there at its acceleration limit, ``sqrt(2 a room)`` (a joint at the end of its range
        gives no retreat that way); None where nothing bounds them."""
        speeds, accelerations = motion.velocity_limits, motion.acceleration_limits
        ranges = self._ranges  # (the robot's ranged 1-DoF joints: PositionLimit's table)
        if speeds is None and (accelerations is None or not ranges.active):
            return None
        out = np.full((2, self.model.nv), np.inf)
        if speeds is not None:
            out[:] = speeds
        if accelerations is not None and ranges.active and motion.q is not None:
            iv, x = ranges.v_index, motion.q[ranges.q_index]
            twice = 2.0 * accelerations[iv]
            out[0, iv] = np.minimum(out[0, iv], np.sqrt(twice * np.maximum(x - ranges.lower, 0.0)))
            out[1, iv] = np.minimum(out[1, iv], np.sqrt(twice * np.maximum(ranges.upper - x, 0.0)))
        return out

    def _carried(self, out: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray | None:
        """How much each bound of ``out``, the rows of this step, rises by the normal velocity
        of the moving obstacle's closest point away from the robot (falls where it comes
        closer): ``n^T (v_b(p_b) - v_a(p_a))`` with ``v_x(p) = v + w x (p - o)`` for an
        obstacle with twist ``(v, w)`` and origin ``o`` (0 for a link of the robot), so that
        the row bounds the pair's relative closing speed (:mod:`sjt_pin.limits.collision`'s
        docstring); None without a moving obstacle."""
        if out is None or not self._moving:
            return None
        count = len(self.active)
        owners = np.concatenate([np.asarray(self.active, dtype=np.int64),
                                 self._owners[:self._witness_count].astype(np.int64)])
        rows = self._pair_rows[:count + self._witness_count]
        normal = rows[:, 4:7]
        shift = np.zeros(len(owners))
        for side, sign, points in ((1, 1.0, rows[:, 10:13]), (0, -1.0, rows[:, 7:10])):
            index = self._pair_obstacle[owners, side]
            mine = np.flatnonzero(index >= 0)
            if mine.size == 0:
                continue
            twist = self._velocity[index[mine]]
            velocity = twist[:, :3]
            if twist[:, 3:].any():  # (a turning obstacle: numpy's cross costs 10-17 us)
                origin = self._placement[self.pairs[owners[mine], side], :3, 3]
                velocity = velocity + np.cross(twist[:, 3:], points[mine] - origin)
            shift[mine] += sign * np.einsum("ij,ij->i", normal[mine], velocity)
        return shift
