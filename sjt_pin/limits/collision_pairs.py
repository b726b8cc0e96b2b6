"""The pairs a :class:`sjt_pin.limits.collision.CollisionLimit` checks: its obstacles added
to the geometry model, the pairs chosen (adjacency, SRDF, ``pairs`` and ``ignore``), the check
at the start (overlaps, margins) and the exact distances and closest points of every pair.

A part of the CollisionLimit (a mixin it inherits from), operating on its state."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .collision_geometry import (
    GJK_TOLERANCE,
    ClosestPoints,
    CollisionError,
    PairDistance,
    _check_extent,
    _supported,
    check_pose,
    coal,
    mesh_hull,
)
from .collision_state import CollisionState


class PairsMixin(CollisionState):
    """The pairs of a :class:`~sjt_pin.limits.collision.CollisionLimit` and their distances."""

    # -- construction ------------------------------------------------------------------------
    def _add_obstacle(self, i: int, item) -> None:
        try:
            shape, pose = item
        except (TypeError, ValueError):
            raise TypeError(f"obstacle {i} must be a (coal shape, pin.SE3) pair, got "
                            f"{type(item).__name__}") from None
        if not _supported(shape):
            raise CollisionError(f"obstacle {i}: unknown shape {type(shape).__name__}; use a "
                                 "coal Sphere, Box, Capsule, Cylinder, Convex or BVHModel")
        check_pose(pose, f"pose of obstacle {i}")
        _check_extent(shape, f"obstacle {i}")
        self._obstacle_shapes.append(shape)
        if self._convex and isinstance(shape, coal.BVHModelBase) and not isinstance(
                shape, coal.ConvexBase):  # a mesh: its hull, as the robot's own meshes
            shape = mesh_hull(shape, f"obstacle {i}")
        obj = pin.GeometryObject(f"obstacle_{i}", 0, 0, pose, shape)
        self._obstacle_ids.append(self.geometry.addGeometryObject(obj))

    def _link(self, g: int) -> str:
        g = int(g)
        if g >= self.n_robot:
            return "world"
        return self.model.frames[self.geometry.geometryObjects[g].parentFrame].name

    def _matches(self, rules, a: int, b: int) -> bool:
        na, nb = self.geometry.geometryObjects[a].name, self.geometry.geometryObjects[b].name
        la, lb = self._link(a), self._link(b)
        for x, y in rules:
            if (x in (na, la) and y in (nb, lb)) or (y in (na, la) and x in (nb, lb)):
                return True
        return False

    def _choose_pairs(self, self_collision, extra, ignore, srdf) -> None:
        geoms = self.geometry.geometryObjects
        names = {g.name for g in geoms} | {self._link(i) for i in range(len(geoms))}
        for rule in extra + ignore:
            if len(rule) != 2 or any(n not in names for n in rule):
                raise ValueError(f"pair {rule!r} names no known link or geometry; known links: "
                                 f"{sorted({self._link(i) for i in range(self.n_robot)})}")
        disabled = set()
        if self_collision and srdf is not None:
            probe = self.geometry.copy()
            probe.addAllCollisionPairs()
            every = {(p.first, p.second) for p in probe.collisionPairs}
            pin.removeCollisionPairs(self.model, probe, str(srdf))
            disabled = every - {(p.first, p.second) for p in probe.collisionPairs}
        parents = self.model.parents
        chosen = []
        n = len(geoms)
        for a in range(n):
            for b in range(a + 1, n):
                ja, jb = geoms[a].parentJoint, geoms[b].parentJoint
                obstacle_a, obstacle_b = a >= self.n_robot, b >= self.n_robot
                if obstacle_a and obstacle_b:
                    continue
                if obstacle_a or obstacle_b:
                    keep = (jb if obstacle_a else ja) != 0  # a link fixed to the world: skip
                else:
                    keep = (self_collision and ja != jb and parents[ja] != jb
                            and parents[jb] != ja and (a, b) not in disabled)
                if not keep and extra and self._matches(extra, a, b):
                    keep = True
                if keep and ignore and self._matches(ignore, a, b):
                    keep = False
                if keep:
                    chosen.append((a, b))
        self._set_pairs(chosen)

    def _set_pairs(self, chosen: list[tuple[int, int]]) -> None:
        """Check the geometry pairs ``chosen`` (indices): the geometry model's pairs, its data
        (coal's requests: signed distances, GJK and EPA to GJK_TOLERANCE) and their names."""
        geoms = self.geometry.geometryObjects
        self.geometry.removeAllCollisionPairs()
        for a, b in chosen:
            self.geometry.addCollisionPair(pin.CollisionPair(a, b))
        self.pairs = np.array(chosen, dtype=np.int64).reshape(-1, 2)
        self.pair_names = [(geoms[a].name, geoms[b].name) for a, b in chosen]
        self.geometry_data = self._new_geometry_data()
        self._probe_data = None  # (distances(), closest_points(), placements(): _probe)
        #: the distance each pair keeps (m): ``margin``, or less for a pair of the robot's own
        #: links that was closer than ``margin`` where the limit started
        self.margins = np.full(len(chosen), self.margin)

    def _new_geometry_data(self):
        """A GeometryData of the pairs: coal's requests for signed distances, GJK and EPA to
        GJK_TOLERANCE, each warm-started from the pair's last query with the state kept in its
        request (``CachedGuess``), where copies carry it (:mod:`.collision_copies`)."""
        data = self.geometry.createData()
        for req in data.distanceRequests:
            req.enable_signed_distance = True
            req.gjk_tolerance = req.epa_tolerance = GJK_TOLERANCE
            req.gjk_initial_guess = coal.GJKInitialGuess.CachedGuess
        return data

    def _distance(self, k: int, data=None):
        return pin.computeDistance(self.geometry, self.geometry_data if data is None else data,
                                   int(k))

    def _probe(self, q: np.ndarray):
        """The geometry at ``q`` for the queries a user asks between steps (distances(),
        closest_points(), placements()), in a GeometryData of their own: in the steps' own, a
        query there changed the next steps (coal's queries keep state from one call to the
        next; SO-101 beside a moving ball, its distances read every step for 6 steps, took
        another path from there, up to 2.5 times the acceleration the unread run took)."""
        if self._probe_data is None:
            self._probe_data = self._new_geometry_data()
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        pin.updateGeometryPlacements(self.model, self._data, self.geometry, self._probe_data)
        return self._probe_data

    def check(self, q: np.ndarray) -> None:
        """Raise :class:`CollisionError` if an obstacle overlaps the robot at ``q``, and take
        ``q`` as the start (what the first step does otherwise): pairs of the robot's links
        that overlap there are dropped, those closer than ``margin`` keep their distance."""
        pin.framesForwardKinematics(self.model, self._data, np.asarray(q, dtype=float))
        self._check(self.model, self._data)

    def _check(self, model, data) -> None:
        """At the start: an obstacle that overlaps the robot is an error; a pair of the robot's
        own links that overlaps (meshes that intersect in the URDF's pose, as adjacent links'
        do) is dropped, with a warning; one closer than ``margin`` keeps its start distance
        as its margin (:attr:`margins`)."""
        pin.updateGeometryPlacements(model, data, self.geometry, self.geometry_data)
        start = np.array([self._distance(k).min_distance for k in range(len(self.pairs))])
        own = (self.pairs[:, 0] < self.n_robot) & (self.pairs[:, 1] < self.n_robot)
        for k in np.flatnonzero(~own & ~(start > 0)):
            a, b = self.pairs[k]
            na, nb = self.pair_names[k]
            raise CollisionError(f"{nb if b >= self.n_robot else na} overlaps "
                                 f"{na if b >= self.n_robot else nb} at the start "
                                 f"(distance {start[k] * 1e3:.1f} mm); move the obstacle or "
                                 "the start configuration")
        overlap = own & ~(start > 0)
        if overlap.any():
            import warnings

            names = [self.pair_names[k] for k in np.flatnonzero(overlap)]
            warnings.warn(f"CollisionLimit: {len(names)} pair(s) of links overlap at the start "
                          f"and are not checked: {names}", stacklevel=4)
            keep = ~overlap
            start = start[keep]
            self._set_pairs([(int(a), int(b)) for a, b in self.pairs[keep]])
            self._prepare_broad_phase()
            pin.updateGeometryPlacements(model, data, self.geometry, self.geometry_data)
        own = (self.pairs[:, 0] < self.n_robot) & (self.pairs[:, 1] < self.n_robot)
        close = own & (start < self.margin)
        self.margins[close] = start[close]
        inside = np.flatnonzero(~own & (start < self.margin))
        if inside.size:
            import warnings

            said = ", ".join(f"{self.pair_names[k][0]} / {self.pair_names[k][1]} at "
                             f"{start[k] * 1e3:.1f} mm" for k in inside)
            warnings.warn(f"CollisionLimit: the robot starts inside the {self.margin * 1e3:g} mm "
                          f"margin of an obstacle ({said}); its rows move it out, within the "
                          "solver's limits", UserWarning, stacklevel=4)
        self._checked = True

    def distances(self, q: np.ndarray) -> list[PairDistance]:
        """Every checked pair at ``q`` with its exact distance (m), closest first."""
        data = self._probe(q)
        out = []
        for k, (a, b) in enumerate(self.pairs):
            d = self._distance(k, data).min_distance
            na, nb = self.pair_names[k]
            out.append(PairDistance(na, nb, self._link(a), self._link(b), float(d)))
        out.sort(key=lambda p: p.distance)
        return out

    def placements(self, q: np.ndarray) -> list[tuple[str, object, np.ndarray]]:
        """The robot's checked geometry at ``q``: ``(name, coal shape, 4x4 world pose)`` for
        each geometry that moves (hulls with ``convex=True``), e.g. to draw it."""
        data = self._probe(q)
        geoms = self.geometry.geometryObjects
        return [(geoms[g].name, geoms[g].geometry, data.oMg[g].homogeneous)
                for g in range(self.n_robot) if geoms[g].parentJoint != 0]

    def closest_points(self, q: np.ndarray, within: float | None = None
                       ) -> list[ClosestPoints]:
        """The checked pairs closer than ``within`` (m; default ``influence``) at ``q``, with
        their closest points, closest first (e.g. to draw them: ``Viewer.show(..., collision=)``).
        """
        within = self.influence if within is None else float(within)
        data = self._probe(q)
        out = []
        for k, (a, b) in enumerate(self.pairs):
            res = self._distance(k, data)
            d = res.min_distance
            if d < within:
                na, nb = self.pair_names[k]
                out.append(ClosestPoints(PairDistance(na, nb, self._link(a), self._link(b),
                                                      float(d)),
                                         np.array(res.getNearestPoint1()),
                                         np.array(res.getNearestPoint2())))
        out.sort(key=lambda p: p.distance)
        return out
