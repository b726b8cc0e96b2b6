"""The rows of a step of :class:`sjt_pin.limits.collision.CollisionLimit`: the cache's key,
each pair's reach at the speed limits, the exact queries and the damper and witness rows
(``kernels.collision_rows``), and the rows formed in Python where a query found no closest
points.

A part of the CollisionLimit (a mixin it inherits from), operating on its state."""

from __future__ import annotations

import numpy as np

from ..kernels import Skip, collision_rows, damper_rows, near_pairs, witness_rows
from .base import Motion
from .collision_geometry import WITNESS_APART
from .collision_state import CollisionState


class RowsMixin(CollisionState):
    """The rows of a step of a :class:`~sjt_pin.limits.collision.CollisionLimit`."""

    def _key(self, q: np.ndarray | None, motion: Motion) -> tuple:
        """What :meth:`rows` answers for, its cache's key: the configuration, the period, the
        obstacles' poses (``_version``) and, with acceleration limits, the joint speeds and
        accelerations; last, the identities of the motion's limits (a copy's first step
        compares their values instead: :meth:`_cached`)."""
        where = None if q is None else q.tobytes()
        accelerations = motion.acceleration_limits
        if accelerations is None:
            return (where, motion.dt, self._version, None, (id(motion.velocity_limits),))
        return (where, motion.dt, self._version, motion.dq.tobytes() + motion.ddq.tobytes(),
                (id(accelerations), id(motion.jerk_limits)))

    @staticmethod
    def _limits_of(motion: Motion) -> tuple:
        """The motion's limits that :meth:`_key` names by identity (references)."""
        if motion.acceleration_limits is None:
            return (motion.velocity_limits,)
        return (motion.acceleration_limits, motion.jerk_limits)

    def _cached(self, data: object, key: tuple, motion: Motion) -> tuple | None:
        """The last rows where they answer for ``key`` on ``data``, else None. A copy's
        carried rows (``_cache[0]`` None: :mod:`.collision_copies`) answer where all but the
        limits' identities agree and the limits' values are those they were made with; they
        are then this solver's."""
        cache = self._cache
        if cache is None:
            return None
        if cache[0] is data and cache[1] == key:
            return cache
        if cache[0] is None and cache[1][:-1] == key[:-1] and all(
                (a is None and b is None) or (a is not None and b is not None
                                              and np.array_equal(a, b))
                for a, b in zip(cache[4], self._limits_of(motion), strict=True)):
            cache = self._cache = (data, key, cache[2], cache[3], self._limits_of(motion))
            return cache
        return None

    def _reach(self, speeds: np.ndarray | None) -> np.ndarray | None:
        """Each pair's reach (npairs,; m/s; kept for these ``speeds``): the fastest its
        distance can shrink at the solver's speed limits (``motion.velocity_limits``, which
        every step it commands keeps), ``sum_j lever_kj v_j`` (:meth:`_pair_levers`). A pair
        whose damper bound ``gain (d - margin) / dt`` is not below it needs no row: no step can
        break it. None without speed limits (``solve()``'s iterations) or levers."""
        reach = None
        if speeds is not None and self._pair_lever is not None:
            finite = np.isfinite(speeds)
            reach = self._pair_lever @ np.where(finite, speeds, 0.0)
            reach[(self._pair_lever[:, ~finite] > 0).any(axis=1)] = np.inf
        self._reaches = (speeds, reach)
        return reach

    def _rows(self, data, dt: float, q: np.ndarray | None, influence: np.ndarray,
              reach: np.ndarray | None, listed: list[int] | None | bool = False
              ) -> tuple[np.ndarray, np.ndarray] | None:
        """rows() at ``q``; ``listed``: ``kernels.near_pairs``' answer at ``q`` with these
        ``influence`` where rows() asked it already (False where it did not)."""
        self.active = []  # indices into self.pairs / self.pair_names of the rows returned
        self.within = []
        self._witness_count = 0
        ref = self._reference
        # a pair's distance changes by at most its levers' bound (_near): one that was beyond
        # influence by more than that at its last query still is; both tests compiled where q
        # is its own tangent space, else _near, _aged and numpy
        if listed is not False:
            stale = listed is None
        elif (self._flat and q is not None and ref is not None and ref[0] == self._version
                and self._floor_q is not None):
            skip = self._skip
            if skip is None:  # (what near_pairs reads, since the last broad phase)
                self._prefilter[0] = -1.0  # (near_pairs orders its test for this gap)
                skip = self._skip = Skip(
                    reference=ref[1], lower=self._lower, upper=self._upper,
                    lever=self._pair_lever, gap=ref[3], near=ref[2], floor=self._floor,
                    floor_q=self._floor_q, prefilter=self._prefilter)
            listed = near_pairs(q, skip, influence)
            stale = listed is None
        else:
            listed, stale = None, False
        if listed is None and q is not None and self._flat and (
                stale or ref is None or ref[0] != self._version):
            listed = self._refresh(data, q, influence)
        if listed is None:
            listed = self._aged(q, self._near(data, q, influence, stale), influence).tolist()
        if not (isinstance(listed, list) and listed):
            return None
        self._data_views(data)
        return self._queried(self._views, listed, influence, reach, dt)

    def _queried(self, views: tuple, listed: list[int], influence: np.ndarray,
                 reach: np.ndarray | None, dt: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The rows of the pairs ``listed`` (:attr:`active`, :attr:`within` and the witness
        count set): the geometries' placements, coal's distance of each pair (those within
        influence get a row, unless it cannot bind at the speed limits: :meth:`_reach`), their
        witnesses' rows and the damper rows of them all, in one compiled call (the Python
        around each query and between the parts cost more than the queries); ``views``:
        :attr:`_views`, ``(data, its views or data itself)``."""
        rate = self.gain / dt
        out = collision_rows(self._tables, listed, views[1], rate, influence, self._tick + 1.0,
                             reach, self._compute)
        if out is None:
            self.active, self.within, self._witness_count = [], [], 0
            return None
        self.within, found, A, b, self._witness_count = out
        self.active = found
        if not found:
            return None
        if A is None:  # a query found no closest points: its row first, then the rest
            return self._formed_rows(views[0], found, rate)
        if self.witnesses:
            self._tick += 1.0
        return A, b

    def _data_views(self, data) -> object:
        """``kernels.collision_rows``' views onto ``data`` (Pinocchio's data of the solver's
        kinematics): ``(data, data.J, [oMi[j].rotation], [oMi[j].translation])``, numpy
        arrays on its own memory that the kernel reads without a Python call (kept while the
        same data comes back); ``data`` itself where Pinocchio's bindings give copies."""
        if self._views[0] is data:
            return self._views[1]
        parts = [data.J] + [getattr(data.oMi[j], name) for name in ("rotation", "translation")
                            for j in range(self.model.njoints)]
        n = self.model.njoints
        views = data if any(part.flags.owndata or part.base is not None for part in parts) \
            else (data, _joint_jacobians(parts[0]), parts[1:1 + n], parts[1 + n:])
        self._views = (data, views)
        return views

    def _formed_rows(self, data, found: list[int], rate: float) -> tuple[np.ndarray, np.ndarray]:
        """The rows of a step where some query found no closest points (:meth:`_centre_rows`
        forms theirs), its witnesses' and the damper rows of them all, as
        ``kernels.collision_rows`` makes them otherwise."""
        self._centre_rows(data, found)
        count = self._witness_rows(data, found) if self.witnesses else len(found)
        A = np.empty((count, self._support.shape[1]))
        b = np.empty(count)
        damper_rows(_joint_jacobians(data.J), self._support, self._pair_rows[:count], rate, A, b)
        if self._mimic is not None:
            A = A @ self._mimic
        A.setflags(write=False)
        b.setflags(write=False)
        return A, b

    def _centre_rows(self, data, found: list[int]) -> None:
        """The rows of the pairs coal found no closest points for (deep in a penetration, as a
        restart of ``solve()`` may start: ``kernels.collision_rows`` marks them ``d = -inf``):
        along the line between the centres of the two geometries' bounding spheres, at the
        depth by which the spheres overlap (at least 1 mm), so that they separate, and the
        configuration is not taken for one within the limit."""
        rows = self._pair_rows
        for i, k in enumerate(found):
            if rows[i, 0] != -np.inf:
                continue
            centres = []
            for g in self.pairs[k]:
                pose = data.oMi[int(self._joint[g])]
                centres.append(pose.rotation @ self._center_local[g, :3] + pose.translation)
            u = centres[1] - centres[0]
            apart = float(np.linalg.norm(u))
            normal = u / apart if apart > 0 else np.array([0.0, 0.0, 1.0])
            overlap = self._radius[self.pairs[k]].sum() - apart
            rows[i, 0] = -max(overlap, 1e-3) if np.isfinite(overlap) else -1e-3
            rows[i, 4:7], rows[i, 7:10], rows[i, 10:13] = normal, centres[0], centres[1]

    def _witness_rows(self, data, found: list[int]) -> int:
        """Append to the step's rows (``_pair_rows[:len(found)]``) one per remembered witness
        of each pair in ``found`` (:mod:`sjt_pin.limits.collision`'s docstring, "Witnesses";
        ``kernels.witness_rows``) and remember this step's closest points; returns the number
        of rows."""
        count = len(found)
        self._tick += 1.0
        total = witness_rows(data.oMi, self._flat_poses, self._pair_rows, found, self._memory,
                             self._memory_state,
                             self._tick, 0.5 * (self.influence - self.margin), WITNESS_APART,
                             self._owners)
        self._witness_count = total - count
        return total


def _joint_jacobians(J: np.ndarray) -> np.ndarray:
    """Pinocchio's WORLD joint Jacobians ``data.J`` as (6, nv): its bindings give a robot of
    one velocity coordinate a vector (6,) (a view of the same memory, reshaped)."""
    return J if J.ndim == 2 else J.reshape(6, 1)
