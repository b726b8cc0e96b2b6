"""The arrays a step of :class:`sjt_pin.limits.collision.CollisionLimit` reads, built once
(and again when pairs are dropped): each geometry's bounding volumes, the pairs as index
arrays and row buffers, the witnesses' memory, the stacked sphere centres of the broad phase,
the Jacobian columns that move each joint, the state of the skip and the levers that bound
how far the joints move a pair.

A part of the CollisionLimit (a mixin it inherits from), operating on its state."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import CollisionTables, Skip
from .collision_geometry import UNBOUNDED, WITNESS_APART, coal
from .collision_reach import joint_extents, joint_translates
from .collision_state import CollisionState


class TablesMixin(CollisionState):
    """The tables of a :class:`~sjt_pin.limits.collision.CollisionLimit`."""

    def _prepare_broad_phase(self) -> None:
        """Everything a step reads, as arrays: each geometry's bounding volumes, the pairs as
        index arrays and row buffers, the witnesses' memory, the stacked sphere centres of the
        broad phase, which Jacobian columns move each joint, and the state of the skip."""
        self._bounding_volumes()
        self._pair_tables()
        self._witness_memory()
        self._sphere_stack()
        self._jacobian_support()
        self._skip_state()
        self._compute = pin.computeDistance  # (kernels.collision_rows calls it for each query)
        self._moving_speeds()

    def _bounding_volumes(self) -> None:
        """Per geometry: its parent joint, coal's local AABB (centre and half extents, in the
        geometry's frame), the sphere around that box, and its placement in the joint's
        frame."""
        geoms = self.geometry.geometryObjects
        n = len(geoms)
        self._joint = np.array([g.parentJoint for g in geoms], dtype=np.int64)
        self._box_center = np.zeros((n, 3))
        self._box_half = np.zeros((n, 3))
        self._radius = np.zeros(n)
        self._placement = np.zeros((n, 4, 4))
        for i, g in enumerate(geoms):
            g.geometry.computeLocalAABB()
            box = g.geometry.aabb_local
            lo, hi = np.array(box.min_), np.array(box.max_)
            if np.all(np.abs(lo) < UNBOUNDED) and np.all(np.abs(hi) < UNBOUNDED):
                self._box_center[i], self._box_half[i] = (lo + hi) / 2, (hi - lo) / 2
                self._radius[i] = float(np.linalg.norm(hi - lo) / 2)
            else:  # a Halfspace or a Plane (coal's box: +-DBL_MAX): always a candidate
                self._box_half[i] = self._radius[i] = np.inf
            self._placement[i] = g.placement.homogeneous

    def _pair_tables(self) -> None:
        """Per pair: its geometries and their joints, the reach of its spheres, and the
        buffer of a step's rows in the form of ``kernels.damper_rows`` (distance, margin,
        the two joints, the normal, the closest points), one per pair and witness."""
        self._pa, self._pb = self.pairs[:, 0].copy(), self.pairs[:, 1].copy()
        ja, jb = self._joint[self._pa], self._joint[self._pb]
        self._joint_table = np.ascontiguousarray(np.column_stack([ja, jb]).reshape(-1, 2),
                                                 dtype=np.int64)
        self._pair_rows = np.zeros((max(len(self.pairs), 1) * (1 + self.witnesses), 13))
        self._span = self._radius[self._pa] + self._radius[self._pb]
        # each pair's obstacles (-1: the robot's geometry) and how far their sphere reaches
        # from their origin (m), for the speed of a moving one (_moving_speeds)
        self._pair_obstacle = self._obstacle_of[self.pairs].reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            self._pair_far = (np.linalg.norm(self._box_center[self.pairs], axis=-1)
                              + self._radius[self.pairs]).reshape(-1, 2)

    def _witness_memory(self) -> None:
        """Per pair: its recent closest points, each in its joint's frame (``witnesses`` rows
        of 6), how many (-1: none ever) and the tick of the last rows() that had it within
        influence (:mod:`sjt_pin.limits.collision`'s docstring, "Witnesses";
        ``kernels.witness_rows``), and that kernel's scratch: the world poses of the joints the
        step's pairs name, the owners of its rows."""
        slots = max(len(self.pairs), 1)
        self._memory = np.zeros((slots * max(self.witnesses, 1), 6))
        self._memory_state = np.zeros((slots, 2))
        self._memory_state[:, 1] = -np.inf
        # a pair with a sphere (or an ellipsoid) has unique closest points, which move
        # continuously with the joints: its own row holds the contact, it remembers nothing
        geoms = self.geometry.geometryObjects
        for k, pair in enumerate(self.pairs):
            if any(isinstance(geoms[int(g)].geometry, (coal.Sphere, coal.Ellipsoid))
                   for g in pair):
                self._memory_state[k, 0] = -1.0
        self._tick = 0.0
        self._owners = np.zeros(slots * max(self.witnesses, 1))
        njoints = self.model.njoints
        self._poses = np.zeros((njoints, 4, 4))
        self._poses[0] = np.eye(4)
        self._flat_poses = self._poses.reshape(njoints, 16)

    def _sphere_stack(self) -> None:
        """The broad phase's products: one product of the stacked poses of the joints that
        carry geometry and the world's identity (4 nj + 4, 4) with every sphere centre in its
        joint's frame (4, n) gives every centre in the world; ``_pick`` takes geometry g's
        xyz out of it (flat indices, (n, 3)) and ``_difference`` the centre differences of
        every pair."""
        n = len(self._joint)
        local = self._placement @ np.append(self._box_center, np.ones((n, 1)), axis=1)[:, :, None]
        self._center_local = local[:, :, 0]
        moving = np.flatnonzero(self._joint != 0)
        self._joints = [int(j) for j in np.unique(self._joint[moving])]
        self._slot = np.searchsorted(self._joints, self._joint)  # joint of g in the stack
        self._slot[self._joint == 0] = len(self._joints)  # the world: an identity at the end
        self._world = np.eye(4)
        self._centers_in = np.ascontiguousarray(self._center_local.T)
        self._pick = (4 * self._slot[:, None] + np.arange(3)) * n + np.arange(n)[:, None]
        D = np.zeros((len(self.pairs), n))
        D[np.arange(len(self.pairs)), self._pa] = 1.0
        D[np.arange(len(self.pairs)), self._pb] -= 1.0
        self._difference = D
        # the sphere-box test pays only where exact distances are dear (meshes)
        self._refine = any(isinstance(g.geometry, coal.BVHModelBase)
                           and not isinstance(g.geometry, coal.ConvexBase)
                           for g in self.geometry.geometryObjects)

    def _jacobian_support(self) -> None:
        """``_support[j]``: the columns of Pinocchio's WORLD joint Jacobians (data.J) that move
        joint j's frame; data.J has a column per joint coordinate, mimic joints' included
        (nvExtended), which ``_mimic`` folds onto the coordinates they follow."""
        model = self.model
        self._support = np.zeros((model.njoints, model.nvExtended))
        for j in range(1, model.njoints):
            for i in model.supports[j]:
                if i > 0:
                    start = model.idx_vExtendeds[i]
                    self._support[j, start:start + model.nvExtendeds[i]] = 1.0

    def _skip_state(self) -> None:
        """The levers that bound how far the joints move a pair (:meth:`_pair_levers`), and
        the state of the skip of the broad phase and of the queries: the last broad phase
        (obstacles' version, q, its pairs, each pair's gap, its pairs as a list) and each
        pair's floor, a lower bound of its exact distance at ``_floor_q`` (m): its distance at
        its last query, less the levers' bound of every move since (:meth:`_aged`); while it
        exceeds influence, the pair is not queried."""
        self._version = 0  # bumped by move(): a new scene
        self._cache: tuple | None = None
        self._kinds, self._extent, self._lower, self._upper = joint_extents(
            self.model, getattr(self, "_mimics", ()))
        self._lever = self._levers()
        # the speed bounds: (dt, the speed limits, whether they let a step cross the band,
        # (lower, upper))
        self._bounds: tuple[float, np.ndarray | None, bool, tuple] | None = None
        self._pair_lever, self._flat = self._pair_levers()
        self._reference: tuple[int, np.ndarray, np.ndarray, np.ndarray, list] | None = None
        self._floor = np.full(len(self.pairs), -np.inf)
        self._prefilter = np.full(1 + 3 * len(self.pairs), -1.0)  # (near_pairs' order)
        self._floor_q: np.ndarray | None = None  # where the floors hold (None: nowhere)
        self._influence = np.full(len(self.pairs), self.influence)  # each pair's, m
        self._braking_influence = np.zeros(len(self.pairs))  # kernels.braking_reach's output
        #: what kernels.collision_rows reads and writes besides the step's (arrays changed in
        #: place only)
        self._tables = CollisionTables(
            geometry=self.geometry, geometry_data=self.geometry_data, model=self.model,
            update=pin.updateGeometryPlacements, floor=self._floor, margins=self.margins,
            joints=self._joint_table, rows=self._pair_rows, memory=self._memory,
            state=self._memory_state, owners=self._owners, support=self._support,
            mimic=self._mimic, keep=0.5 * (self.influence - self.margin), apart=WITNESS_APART,
            witnesses=self.witnesses > 0)
        self._skip: Skip | None = None  # near_pairs' (from _reference and _floor_q)
        self._views: tuple = (None, None)  # (a data, collision_rows' views onto it)
        # each pair's reach at the solver's speed limits (_reach): (those limits, the reach)
        self._reaches: tuple[object, np.ndarray | None] = (self, None)  # (none yet)

    def _chains(self, unbounded: float) -> tuple[np.ndarray, np.ndarray]:
        """For each geometry g and joint coordinate (nvExtended) of a joint k that moves it:
        a bound (m) on the distance from joint k's origin to any point of g's bounding
        sphere, over every configuration with the translating joints in their ranges
        (:func:`joint_extents`): the sphere's far side from g's joint, plus, for each joint i from
        g's joint up to (not including) k, its fixed offset (``jointPlacements``) and how far
        its own motion can carry its frame (a prismatic joint's extension); ``unbounded``
        stands for the extension of a joint without a finite range. And which coordinates
        move g at all. The sum of :meth:`_levers` and :meth:`_pair_levers`."""
        model = self.model
        n = len(self.geometry.geometryObjects)
        extent = np.where(np.isfinite(self._extent), self._extent, unbounded)
        chain = np.zeros((n, model.nvExtended))
        moves = np.zeros((n, model.nvExtended), dtype=bool)
        for g in range(n):
            k = int(self._joint[g])
            length = float(np.linalg.norm(self._center_local[g, :3]) + self._radius[g])
            while k > 0:
                start = model.idx_vExtendeds[k]
                span = slice(start, start + model.nvExtendeds[k])
                chain[g, span] = length
                moves[g, span] = True
                length += float(np.linalg.norm(model.jointPlacements[k].translation)) + extent[k]
                k = model.parents[k]
        return chain, moves

    def _pair_levers(self) -> tuple[np.ndarray | None, bool]:
        """For each pair and velocity coordinate, a bound (m per unit) on how much the
        coordinate changes the distance between any two points of the pair's bounding
        spheres, at every configuration whose translating joints lie in their ranges
        (:attr:`_inside`): :meth:`_chains` to the far side of either sphere when it moves only
        one of them (at least 1 m for a joint that translates: a prismatic joint's own
        displacement moves the geometry 1:1), 0 when it moves both (rigidly together), summed
        over the joints it drives (a mimic joint's times its multiplier); and whether ``q`` is
        its own tangent space (revolute and prismatic joints, mimic joints following them).
        ``None`` (no skip) for joints whose coordinates are not rates of a motion (Euler
        angles), or when a joint without a finite range of translation lies between a pair's
        geometry and a joint that moves it."""
        model = self.model
        kinds = self._kinds
        if any("ZYX" in kind for kind in kinds[1:]):
            return None, False
        flat = model.nq == model.nv and all(model.nqs[j] == model.nvs[j] <= 1
                                             for j in range(1, model.njoints))
        chain, moves = self._chains(np.inf)
        translates = np.zeros(model.nvExtended, dtype=bool)
        for k in range(1, model.njoints):
            start = model.idx_vExtendeds[k]
            translates[start:start + model.nvExtendeds[k]] = joint_translates(kinds[k])
        lever = np.where(translates, np.maximum(chain, 1.0), chain)
        lever[~moves] = 0.0
        one = moves[self._pa] != moves[self._pb]
        pair = np.where(one, lever[self._pa] + lever[self._pb], 0.0)
        if not np.isfinite(pair).all():
            return None, False
        if self._mimic is not None:
            pair = pair @ np.abs(self._mimic)
        return pair, flat

    def _levers(self) -> np.ndarray:
        """For each velocity coordinate, a bound (m per unit) on the speed it gives any point of
        the geometry it moves: the longest of :meth:`_chains` (triangle inequality), or at
        least 1 m for a joint that translates (prismatic, planar, free-flyer). A joint without
        a finite range of translation counts at its origin here (these bounds only keep steps
        small, :meth:`bounds`; the broad phase's skip does not use them)."""
        model = self.model
        chain, _ = self._chains(0.0)
        reach = chain[:self.n_robot].max(axis=0) if self.n_robot else np.zeros(model.nvExtended)
        lever = np.zeros(model.nvExtended)
        for j in range(1, model.njoints):
            start = model.idx_vExtendeds[j]
            span = slice(start, start + model.nvExtendeds[j])
            lever[span] = (np.maximum(reach[span], 1.0) if joint_translates(self._kinds[j])
                           else reach[span])
        if self._mimic is not None:  # a coordinate's lever: the largest of the joints it drives
            lever = (np.abs(self._mimic) * lever[:, None]).max(axis=0)
        return lever
