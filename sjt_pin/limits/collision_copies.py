"""Copies of :class:`sjt_pin.limits.collision.CollisionLimit` (``pickle``, ``copy.deepcopy``,
another process): the limit made anew from its arguments and the robot's own geometry, with
every memory its next steps read, so that a copy's steps are the original's, bitwise:

- the start's check: the pairs it kept and the distance each keeps (``margins``);
- the witnesses: each pair's remembered closest points and the tick they were seen at;
- the broad phase's skip: its last result, the pairs' floors and where they hold;
- each pair's GJK warm start: the last separating direction and support vertices, which
  coal keeps in the pair's ``DistanceRequest`` (``GJKInitialGuess.CachedGuess``, set where
  the limit makes its requests): distances converge to ``GJK_TOLERANCE`` from wherever
  they start, so two starts agree to that tolerance, not bitwise, and a copy's first
  queries must start where the original's would.

- the rows of the last configuration, which the next step at the same configuration and
  motion answers from without a query (an arm at rest): a copy that queried them again
  advanced its witnesses' clock a tick past the original's, and UR5 resting above a table
  then parted from its copy once it moved on. A copy's solver names its limits by other
  arrays: the carried rows answer where their values agree (``RowsMixin._cached``).

A copy loaded in another process steps alike too: coal's process-wide state is settled
before any limit's first query (``collision_geometry.settle_coal``).

A part of the CollisionLimit (a mixin it inherits from), operating on its state."""

from __future__ import annotations

import numpy as np

from .collision_geometry import coal
from .collision_state import CollisionState


class CopiesMixin(CollisionState):
    """What a copy of a :class:`~sjt_pin.limits.collision.CollisionLimit` carries."""

    def __getstate__(self) -> dict:
        """Pickled as its arguments (obstacles at their current poses), the robot's own
        collision geometry (the robot pickles without it; coal's hulls do not pickle, they
        are built again; an obstacle given as a bare ``coal.ConvexBase``, a hull built without
        its triangles, cannot be copied: TypeError), the obstacles' velocities and the
        memories of the module docstring."""
        for i, shape in enumerate(self._obstacle_shapes):
            if isinstance(shape, coal.ConvexBase) and not isinstance(shape, coal.Convex):
                raise TypeError(f"obstacle {i} is a coal.ConvexBase without its triangles, "
                                "which coal cannot copy or pickle: build it with them "
                                "(mesh.buildConvexHull(True, 'Qt'), coal.Convex(points, "
                                "triangles)) or give the mesh itself")
        return {"args": {**self._args, "obstacles": self.obstacles},
                "geometry": self._source.copy(), "velocity": self._velocity.copy(),
                "stamps": [None if s is None else (s[0], s[1].copy()) for s in self._stamps],
                "memory": self._memories()}

    def __setstate__(self, state: dict) -> None:
        self._restored_geometry = state["geometry"]
        self.__init__(**state["args"])  # type: ignore[misc]
        self._velocity[:] = state.get("velocity", 0.0)
        self._stamps = state.get("stamps", self._stamps)
        self._moving_speeds()
        if state.get("memory") is not None:
            self._remember(state["memory"])

    def _memories(self) -> dict:
        """The memories a copy carries (module docstring), as copies."""
        ref = self._reference
        return {
            "pairs": self.pairs.copy(), "checked": self._checked, "margins": self.margins.copy(),
            "witnesses": (self._memory.copy(), self._memory_state.copy(), self._owners.copy(),
                          self._tick),
            "broad_phase": (self._version, None if ref is None else (
                ref[0], ref[1].copy(), ref[2].copy(), ref[3].copy(), list(ref[4])),
                self._floor.copy(), None if self._floor_q is None else self._floor_q.copy()),
            "guesses": [(np.array(r.cached_gjk_guess), np.array(r.cached_support_func_guess))
                        for r in self.geometry_data.distanceRequests],
            "rows": None if self._cache is None else _carried_rows(self._cache)}

    def _remember(self, memory: dict) -> None:
        """Take the memories of :meth:`_memories` (written into the arrays the compiled
        tables read, in place)."""
        pairs = memory["pairs"]
        if not np.array_equal(pairs, self.pairs):  # (the start's check dropped some)
            self._set_pairs([(int(a), int(b)) for a, b in pairs])
            self._prepare_broad_phase()
        self.margins[:] = memory["margins"]
        self._checked = memory["checked"]
        points, state, owners, self._tick = memory["witnesses"]
        self._memory[:], self._memory_state[:], self._owners[:] = points, state, owners
        self._version, self._reference, floor, self._floor_q = memory["broad_phase"]
        self._floor[:] = floor
        for request, (ray, support) in zip(self.geometry_data.distanceRequests,
                                           memory["guesses"], strict=True):
            request.cached_gjk_guess = ray
            request.cached_support_func_guess = support
        rows = memory.get("rows")
        self._cache = None if rows is None else _carried_rows(rows)


def _frozen(x):
    """``x`` (an array, a tuple or list of them, or an immutable value) as a copy, its arrays
    read-only as the cached rows' are (pickle and deepcopy give writable arrays)."""
    if isinstance(x, np.ndarray):
        y = x.copy()
        y.setflags(write=False)
        return y
    if isinstance(x, tuple | list):
        return type(x)(_frozen(y) for y in x)
    return x


def _carried_rows(cache: tuple) -> tuple:
    """The rows cache a copy carries, as copies: (the kinematics data they were made on: left
    out, the key, the limit's state they set, the rows, the values of the motion's limits)."""
    _, key, state, out, limits = cache
    return (None, (*key[:-1], None), _frozen(state), _frozen(out), _frozen(limits))
