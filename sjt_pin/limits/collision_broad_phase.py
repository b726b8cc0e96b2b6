"""The broad phase of :class:`sjt_pin.limits.collision.CollisionLimit` and its skip: the
pairs whose bounding volumes come within influence, reused while the levers' bound of the
joints' moves cannot have closed a gap (as a Verlet list), and the floors that keep a pair
beyond influence from being queried again (module docstring of
:mod:`sjt_pin.limits.collision`, last paragraph).

A part of the CollisionLimit (a mixin it inherits from), operating on its state."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import refresh_pairs, sphere_gaps
from .collision_state import CollisionState


class BroadPhaseMixin(CollisionState):
    """The broad phase of a :class:`~sjt_pin.limits.collision.CollisionLimit`."""

    # -- broad phase -------------------------------------------------------------------------
    def _broad_phase(self, data, influence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pairs whose bounding volumes come within their ``influence`` (npairs,; indices
        into pairs), and for each pair the gap (m) between its bounding volumes.

        Each geometry has a box in its own frame (coal's local AABB) and the sphere around it.
        First the spheres of both (for every pair), then, where exact distances are dear
        (meshes), for the few pairs left, the sphere of either one against the other's box:
        volumes contain their geometry, so neither test drops a pair within its influence."""
        views = self._data_views(data)
        if views is not data and not self._refine:  # (compiled: joint poses read in place)
            gap = self._sphere_gaps(views)
            return np.flatnonzero(gap < influence), gap
        oMi = data.oMi.tolist()
        H = np.concatenate([oMi[j].homogeneous for j in self._joints] + [self._world])
        center = (H @ self._centers_in).take(self._pick)
        diff = self._difference @ center
        gap = np.sqrt(np.einsum("ij,ij->i", diff, diff)) - self._span
        near = np.flatnonzero(gap < influence)
        if near.size == 0 or not self._refine:
            return near, gap
        # both directions at once: the sphere of a against b's box, and of b against a's box
        one = np.concatenate((self._pa[near], self._pb[near]))
        other = np.concatenate((self._pb[near], self._pa[near]))
        poses = H.reshape(-1, 4, 4)[self._slot[other]] @ self._placement[other]
        box_gap = (self._sphere_box(center[one], poses, other) - self._radius[one]).reshape(2, -1)
        gap[near] = np.maximum(box_gap[0], box_gap[1])
        return np.flatnonzero(gap < influence), gap

    def _near(self, data, q: np.ndarray | None, influence: np.ndarray,
              stale: bool = False) -> np.ndarray:
        """:meth:`_broad_phase`'s pairs at ``q``, from the last broad phase while ``q`` is close
        to where it ran: a displacement ``dq`` from there changes the distance of a pair's
        bounding spheres by at most ``sum_j lever_j |dq_j|`` (:meth:`_pair_levers`), so a
        pair it left out stays out until that plus its influence reaches the gap it left the
        pair at (``stale``: ``kernels.near_pairs`` found it does). A new broad phase keeps the
        floors of the pairs it had before (the others have none)."""
        inside = q is not None and self._inside(q)
        ref = self._reference if inside and self._reference is not None \
            and self._reference[0] == self._version else None  # (None: floors gone too)
        if ref is not None and q is not None and not stale:  # (ref: q inside the box)
            if (self._pair_lever @ self._moved(ref[1], q) + influence < ref[3]).all():
                return ref[2]
        near, gap = self._broad_phase(data, influence)
        if q is not None and inside and self._pair_lever is not None:
            # the pairs within a skin of half the band (influence - margin) of being candidates
            # are candidates too, as in a Verlet list: the next broad phase waits until some
            # bound reaches the skin at least (Panda's scenes: on 1-3 % of the steps instead
            # of 8-16 %), and an extra candidate costs one exact query (its floor skips it
            # after that; a wider skin queries more than it saves)
            near = np.flatnonzero(gap < influence + 0.5 * (self.influence - self.margin))
            gap[near] = np.inf  # a candidate stays one
            kept = np.full(len(self.pairs), -np.inf)
            if ref is not None:  # (after a move() of an obstacle the floors are gone)
                kept[ref[2]] = self._floor[ref[2]]
            self._floor[:] = kept
            self._reference = (self._version, q.copy(), near, gap, near.tolist())
        else:
            self._reference = None  # no reference outside the box the levers hold in
            self._floor.fill(-np.inf)
            self._floor_q = None
        self._skip = None
        return near

    def _refresh(self, data, q: np.ndarray, influence: np.ndarray) -> list[int] | None:
        """A new broad phase at ``q`` and the pairs to query, as :meth:`_near` (stale) then
        :meth:`_aged` make them, in two compiled calls (``kernels.sphere_gaps`` and
        ``kernels.refresh_pairs``); None (nothing changed) where those do not apply: the
        sphere-box refinement, no levers, the views missing, ``q`` outside the box the
        levers hold in."""
        views = self._data_views(data)
        if views is data or self._refine or self._pair_lever is None:
            return None
        gap = self._sphere_gaps(views)
        ref = self._reference
        kept = ref[4] if ref is not None and ref[0] == self._version else None
        out = refresh_pairs(q, self._lower, self._upper, gap, influence,
                            0.5 * (self.influence - self.margin), self._floor, kept,
                            self._floor_q, self._pair_lever)
        if out is None:
            return None
        near, listed = out
        self._reference = (self._version, q.copy(), np.array(near, dtype=np.intp), gap, near)
        if self._floor_q is None:
            self._floor_q = q.copy()
        self._skip = None
        return listed

    def _sphere_gaps(self, views) -> np.ndarray:
        """The gap (m) between the bounding spheres of each pair (npairs,), from the joint
        poses the ``views`` (:meth:`_data_views`) read in place (``kernels.sphere_gaps``)."""
        gap = np.empty(len(self.pairs))
        sphere_gaps(views, self._joint, self._center_local, self.pairs, self._span, gap)
        return gap

    def _aged(self, q: np.ndarray | None, near: np.ndarray, influence: np.ndarray) -> np.ndarray:
        """The pairs of ``near`` (the last broad phase's, :meth:`_near`) to query at ``q``:
        those whose floor, aged from ``_floor_q`` to ``q`` by the levers' bound, is within
        their influence (every pair where the floors hold nowhere)."""
        lever = self._pair_lever
        if q is None or self._reference is None or lever is None:
            return near
        if self._floor_q is None:  # (every floor is -inf: _near)
            self._floor_q = q.copy()
            self._skip = None
            return near
        self._floor[near] -= lever[near] @ self._moved(self._floor_q, q)
        self._floor_q[:] = q
        return near[self._floor[near] <= influence[near]]

    def _moved(self, start: np.ndarray, q: np.ndarray) -> np.ndarray:
        """|q - start| per velocity coordinate (rad, m; on the manifold where q is not its own
        tangent space), what :meth:`_pair_levers` multiply."""
        return np.abs(q - start if self._flat else pin.difference(self.model, start, q))

    def _inside(self, q: np.ndarray) -> bool:
        """Whether ``q`` lies in the box of position limits :meth:`_pair_levers` holds in."""
        return bool(np.all(q >= self._lower) and np.all(q <= self._upper))

    def _sphere_box(self, points, poses, g) -> np.ndarray:
        """Distance of world ``points`` (k, 3) to the local boxes of geometries ``g``."""
        local = np.einsum("kji,kj->ki", poses[:, :3, :3], points - poses[:, :3, 3])
        outside = np.maximum(np.abs(local - self._box_center[g]) - self._box_half[g], 0.0)
        return np.sqrt(np.einsum("ki,ki->k", outside, outside))
