"""The centre of mass kept over the feet: its ground projection inside the support polygon.

The support polygon is the convex hull of the contacts' sole corners projected on the ground
(the world's xy plane, z up): a quadruped's point feet (``sole=0``) span a quadrilateral, a
humanoid's two soles a hexagon. Each edge k of the hull, with inward unit normal ``n_k`` and
offset ``h_k``, gives the signed distance ``d_k = n_k^T c_xy - h_k`` of the centre of mass's
projection (positive inside), and one velocity-damper row, as the collision limit's
(:mod:`.collision`, after Kanoun, Lamiraux and Wieber, IEEE T-RO 2011, eq. 14):

    d_k_dot >= -gain (d_k - margin) / dt,   d_k_dot = n_k^T J_c,xy q_dot

(``J_c`` Pinocchio's centre-of-mass Jacobian): per period the projection's excess over the
margin shrinks by at most the fraction ``gain``, so it never crosses the margin, and from
outside it the rows pull it back in. Beside acceleration limits the closing speed toward each
edge is also cut to what half of them can brake within the excess (``stoppable_rows``, as for
collisions), with the deceleration the held contacts leave: the rows projected onto the
velocities that keep the contacts (three rows a point foot, six a sole), and their braking
scaled to what such a velocity gives, the joint nearest its limit setting it (without it, the
body reached the margin faster than its held legs could stop it, and the acceleration limits
gave way). This is the static-balance criterion (the centre of mass over the support): it
holds for slow motions, not for dynamic gaits (a ZMP or centroidal criterion).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from ..kernels import stoppable_rows
from ..model_measures import check_mass
from ..robot_frames import find_frame
from ..validation import real_number
from .base import BRAKING_SHARE, EASING_SLACK, Limit, Motion


def convex_hull(points: np.ndarray) -> np.ndarray:
    """The vertices (k, 2) of the convex hull of ``points`` (n, 2), counter-clockwise, without
    collinear ones (Andrew's monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 12)))

    def half(sequence):
        chain: list[tuple[float, float]] = []
        for p in sequence:
            while len(chain) >= 2 and ((chain[-1][0] - chain[-2][0]) * (p[1] - chain[-2][1])
                                       - (chain[-1][1] - chain[-2][1]) * (p[0] - chain[-2][0])
                                       ) <= 0.0:
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(reversed(pts))
    return np.array(lower[:-1] + upper[:-1], dtype=float).reshape(-1, 2)


def sole_corners(sole) -> np.ndarray:
    """A sole's corners (4, 3) in its contact frame for half-sizes ``sole = (hx, hy)`` (m), or
    the frame's origin (1, 3) for a point foot (0, 0)."""
    hx, hy = sole
    if hx > 0 or hy > 0:
        return np.array([[hx, hy, 0.0], [hx, -hy, 0.0], [-hx, -hy, 0.0], [-hx, hy, 0.0]])
    return np.zeros((1, 3))


def support_polygon(placements, corners: np.ndarray, contacts=None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The support polygon of soles with ``corners`` (k, 3) at ``placements`` (``pin.SE3``,
    world): its vertices (m, 2; counter-clockwise), the edges' inward unit normals (m, 2) and
    offsets (m,), a point ``p`` of the ground being ``n_k^T p - h_k`` inside edge k.
    ``ValueError`` (naming ``contacts``) where the soles span no area."""
    points = np.concatenate([corners @ M.rotation.T + M.translation for M in placements])
    hull = convex_hull(points[:, :2])
    edges = np.roll(hull, -1, axis=0) - hull
    lengths = np.linalg.norm(edges, axis=1)
    if len(hull) < 3 or lengths.min() <= 1e-9 or _area(hull) <= 1e-9:
        raise ValueError(f"the contacts {contacts} span no area on the ground (a point or a "
                         "segment): give sole= their size, or more contacts")
    normals = np.column_stack([-edges[:, 1], edges[:, 0]]) / lengths[:, None]
    return hull, normals, np.einsum("ij,ij->i", normals, hull)


class SupportLimit(Limit):
    """The centre of mass's ground projection held ``margin`` inside the support polygon.

    Args:
        contacts: the contact frames (feet, or hands on a support), at least one.
        sole: half the sole's length and width (m) in each contact frame's x and y axes: a
            number (a square sole), a pair ``(hx, hy)``, or 0 for point feet (the default;
            three or more contacts then span the polygon).
        margin: how far inside the polygon (m, >= 0) the projection stays.
        gain: the damper's gain in (0, 1]: per period the excess ``d - margin`` may shrink by
            at most that fraction.

    The polygon is taken from the contacts' poses at the first step and kept (contacts that
    hold do not move); :meth:`update` takes it again after the feet moved. ``polygon`` holds
    its vertices (k, 2; m, world x and y, counter-clockwise) after the first step, and
    ``distance`` the projection's least distance to its edges (m, negative outside).
    """

    name = "support"

    def __init__(self, contacts: Sequence[str], sole=0.0, margin: float = 0.02,
                 gain: float = 0.5):
        if isinstance(contacts, str):
            contacts = [contacts]
        contacts = list(contacts)
        if not contacts or not all(isinstance(c, str) for c in contacts):
            raise TypeError(f"contacts must be one or more frame names, got {contacts!r}")
        sole = np.broadcast_to(np.asarray(sole, dtype=float), (2,)) if np.ndim(sole) == 0 \
            else np.asarray(sole, dtype=float)
        if sole.shape != (2,) or not np.all(np.isfinite(sole)) or np.any(sole < 0):
            raise ValueError(f"sole must be a half-size >= 0 (m) or a pair (hx, hy), got {sole!r}")
        self.margin = real_number(margin, "margin", "m")
        self.gain = real_number(gain, "gain")
        if not 0.0 <= self.margin < np.inf:
            raise ValueError(f"margin must be a finite distance >= 0 (m), got {margin!r}")
        if not 0.0 < self.gain <= 1.0:
            raise ValueError(f"gain must be in (0, 1], got {gain!r}")
        self.contacts = contacts
        self._corners = sole_corners(sole)  # in the contact frame
        self._contact_rows = 3 if not np.any(sole) else 6  # a point foot holds its position
        self._frames: list[int] | None = None
        self.polygon: np.ndarray | None = None
        # the edges' inward and outward unit normals (k, 2) and offsets, the rows' buffers
        self._normals = self._outward = np.zeros((0, 2))
        self._offsets = self._b = self._d = np.zeros(0)
        self._A = np.zeros((0, 0))

    @property
    def distance(self) -> float:
        """The centre of mass's projection's least distance (m, negative outside) to the
        polygon's edges at the last :meth:`rows` (NaN before it): taken when read, not at
        every step."""
        return self._d.min() if self._d.size else np.nan

    def update(self) -> None:
        """Take the polygon again from the contacts' poses at the next step."""
        self.polygon = None

    def _polygon(self, kinematics) -> None:
        model = kinematics.model
        if self._frames is None:  # (found as the tasks find their frames)
            check_mass(model, model.name, "SupportLimit")
            self._frames = [find_frame(model, c, None, "the robot") for c in self.contacts]
        hull, normals, offsets = support_polygon(
            [kinematics.placement(f) for f in self._frames], self._corners, self.contacts)
        self.polygon, self._normals, self._outward = hull, normals, -normals
        self._offsets = offsets
        self._A = np.zeros((len(hull), model.nv))
        self._b, self._d = np.zeros(len(hull)), np.zeros(len(hull))

    def rows(self, kinematics, motion: Motion):
        """Rows ``A q_dot <= b`` (A: (k, nv) in m per unit of q_dot, b: (k,) in m/s), one per
        edge of the support polygon: ``-n_k^T J_c,xy q_dot <= gain (d_k - margin) / dt``."""
        first = self.polygon is None
        if first:
            self._polygon(kinematics)
        c, Jc = kinematics.center_of_mass()
        d = np.matmul(self._normals, c[:2], out=self._d)
        d -= self._offsets
        if first and self.distance < self.margin:
            warnings.warn(f"the centre of mass starts {self.distance:.4g} m inside the support "
                          f"polygon of {self.contacts}, less than the margin {self.margin:g} m: "
                          "the support limit moves it in", stacklevel=2)
        A = np.matmul(self._outward, Jc[:2], out=self._A)
        rate = self.gain / motion.dt
        b = np.subtract(d, self.margin, out=self._b)
        b *= rate
        if motion.acceleration_limits is not None:
            held, share = self._held(kinematics, A, motion.acceleration_limits)
            jerks = None if motion.jerk_limits is None else share * motion.jerk_limits
            stoppable_rows(held, b, motion.dq, motion.ddq, share * motion.acceleration_limits,
                           jerks, rate, motion.dt, BRAKING_SHARE, EASING_SLACK,
                           motion.acceleration_limits, motion.jerk_limits)
        return A, b

    def _held(self, kinematics, A: np.ndarray, accelerations: np.ndarray
              ) -> tuple[np.ndarray, float]:
        """The rows ``A P`` (P the projector onto the velocities that keep the contacts, from
        their world-aligned Jacobians: linear rows of a point foot, all six of a sole), and the
        share of each joint's acceleration limit that braking along them may count on: along
        ``a_i P`` the joint nearest its limit sets the rate, ``|a_i P|^2 min_j(A_j / |a_i P|_j)``,
        against the ``sum_j |a_i P|_j A_j`` that ``stoppable_rows`` assumes (the least share
        over the rows)."""
        frames = self._frames
        assert frames is not None  # (found at the first rows())
        H = np.concatenate([kinematics.world_aligned_jacobian(f)[:self._contact_rows]
                            for f in frames])
        gram = H @ H.T
        gram[np.diag_indices_from(gram)] += 1e-12 * max(np.trace(gram), 1e-300)
        held = A - (A @ H.T) @ np.linalg.solve(gram, H)
        magnitude = np.abs(held)
        assumed = magnitude @ accelerations
        counted = (assumed > 0.0) & np.isfinite(assumed)  # (rows the held legs can move)
        if not counted.any():
            return held, 1.0
        with np.errstate(divide="ignore"):
            rate = np.min(accelerations / magnitude[counted], axis=1)
        gives = np.einsum("ij,ij->i", held[counted], held[counted]) * rate
        return held, float(np.clip(np.min(gives / assumed[counted]), 0.0, 1.0))

    def __repr__(self) -> str:
        return f"SupportLimit({self.contacts!r}, margin={self.margin:g})"


def _area(polygon: np.ndarray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
