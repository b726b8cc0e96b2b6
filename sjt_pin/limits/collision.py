"""Collision avoidance as linear inequalities on the joint velocity: velocity dampers.

Each pair of geometries (robot link / world obstacle, or two robot links) closer than
``influence`` contributes one row on the relative normal velocity of its closest points, the
velocity damper of Faverjon and Tournassoud (ICRA 1987) in the form of Kanoun, Lamiraux and
Wieber (IEEE T-RO 2011, eq. 14):

    d_dot >= -gain (d - margin) / dt,    d_dot = n^T (J_a(p_a) - J_b(p_b)) q_dot

with ``p_a``, ``p_b`` the closest points, ``n`` the unit normal from ``b`` to ``a`` and
``J_x(p)`` the world-aligned linear Jacobian of the point ``p`` fixed to geometry ``x``'s parent
joint (zero for an obstacle). Over one period ``dt`` the distance then changes to first order
by ``d_dot dt >= -gain (d - margin)``: with ``gain`` in (0, 1] it never crosses ``margin``,
and below ``margin`` (or in penetration) the row pushes the pair apart, where its lever
``|A_i|`` is at least ``kernels.PUSH_LEVER`` (1 cm per unit of joint motion); a link with a
shorter one turns about a point near its closest one rather than away, over more than a
radian for a centimetre, and its row only keeps the pair from closing (``b_i = 0``; a row
whose norm is at most ``kernels.ROUNDING_LEVER`` is rounding, set to 0). Where the solver's
speed limits ``v`` keep ``|d_dot|`` below ``gain (d - margin) / dt`` already (``|d_dot| <=
sum_j lever_j v_j``, the levers of the broad phase's skip, below), the row is implied by them
and is left out of the step's rows.

Acceleration limits. A damper alone lets a pair close at up to ``gain (d - margin) / dt``, far
more than an arm with acceleration limits can stop from in the gap left, so a solver with
acceleration limits (``Motion.acceleration_limits``) also bounds each row's closing speed by
what half of those limits can still brake within ``d - margin`` (a braking-distance bound,
the discrete form of ``d_dot >= -sqrt(2 a (d - margin))``; ``kernels.stoppable_rows``): the
arm slows as it nears the margin instead of stopping at it in one period. Under a jerk limit
that bound also counts the row's acceleration toward the margin: a closing speed the row
reaches by speeding up is allowed only if, from that speed and that acceleration, the jerk-
limited braking still stops within ``d - margin`` (``largest_stoppable``, the joints' own
position braking; a pair sliding 0.1 mm from its margin and speeding up at 6 m/s^2 otherwise
reached it at 21 mm/s). The row's jerk is what its joints give, each ramping its own
deceleration at its own limit: below the summed jerks where some already brake at their limit
or speed the row up (the chord of those ramps; the summed jerks let xArm7's wrist link, at
jerk limits 173 times its acceleration limits, close on a ring's hull too fast to stop). A
row whose closing speed jumps (a contact's closest points slide onto another feature, a
witness row appears) eases in: it asks that speed to drop no faster than
the limits allow from the previous step's velocity and acceleration (the share of the row's
acceleration and jerk, and never more than the joints' acceleration and jerk boxes give it
this period: a joint already braking at its limit gives nothing more), as long as the pair,
braking at its whole acceleration (under a jerk limit ramped to it from the acceleration the
step leaves, ``largest_stoppable``), stays ``margin - EASING_SLACK`` apart. A row that appears
at ``influence`` could not stop a pair closing at arm speeds (a link at 1.5 m/s needs some
14 cm at 10 rad/s^2), so each pair's influence grows to the distance within which the row may
have to start braking it: its joints' speeds after this step bound its closing speed ``s``
(the levers of the broad phase's skip, below), the time ``T`` the joints take to stop at their
limits bounds ``s`` over the row's acceleration, and ``s (dt + ramp + T / (2 share))`` covers
what the row needs (``kernels.braking_reach``; a robot whose joints give no such bound, Euler
angles or a translation without a range, keeps ``influence``). The acceleration limit still
yields where the rows ask more than its share at once (several contacts, a row that jumps);
``StepInfo.limit_conflicts`` says so on those steps.

Witnesses. Where two hulls touch along a face or an edge their closest points are not unique,
and coal's pick jumps from one end of the contact to the other as the pair slides or turns: one
row at a time lets the arm turn about the point it keeps, the next step's row (the other end)
turns it back, and at a blocked target the arm chatters in a limit cycle. So each pair also
keeps a few of its recent closest points (fixed to their geometries) as rows of their own, on
the current normal ``n``: for points ``a'`` of geometry a and ``b'`` of b, the plane through
the closest points separates the hulls, so ``s = n^T (b' - a') >= d``; a row
``s_dot >= -gain (s - margin) / dt`` asks nothing the pair's own row does not imply to first
order, but together they hold the whole contact (the several points of a contact manifold),
and the arm comes to rest there. A witness is forgotten when its ``s`` exceeds ``d`` by half
the band ``influence - margin`` or when the pair leaves ``influence``, and a pair farther
than that from its margin remembers nothing (its row binds nothing); nor does a pair with a
sphere (or an ellipsoid), whose closest points are unique and move continuously.

Moving obstacles: an obstacle moved with its velocity bounds each of its pairs' rows by the
relative closing speed (``sjt_pin.limits.collision_moving`` states the guarantee).

Distances and closest points come from coal on the shapes of Pinocchio's ``GeometryModel``:
Pinocchio's ``computeDistance``, called back from the compiled step of the limit
(``kernels.collision_rows``) for each pair it must query. Only the pairs whose bounding
spheres come within ``influence`` (plus a skin of half the band ``influence - margin`` while the
broad phase's result is reused, as in a Verlet list) pay for an exact distance query, and a pair
whose last exact distance was beyond ``influence`` is not queried again until the joints'
moves since can have closed the gap (the joint offsets and prismatic ranges between, summed
step by step: :meth:`CollisionLimit._near`, :meth:`CollisionLimit._aged`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import pinocchio as pin

from ..kernels import braking_reach, near_pairs, stoppable_rows
from .base import BRAKING_SHARE, EASING_SLACK, Limit, Motion
from .collision_broad_phase import BroadPhaseMixin
from .collision_copies import CopiesMixin
from .collision_geometry import (
    ClosestPoints,
    CollisionError,
    PairDistance,
    coal,
    collision_model_of,
    settle_coal,
    srdf_of,
    to_hulls,
)
from .collision_moving import MovingMixin
from .collision_pairs import PairsMixin
from .collision_reach import mimic_map
from .collision_rows import RowsMixin
from .collision_tables import TablesMixin
from .position import PositionLimit

__all__ = ["ClosestPoints", "CollisionLimit", "CollisionError", "PairDistance"]

#: the most recent closest points a pair may keep as rows of their own (``witnesses``): a
#: contact manifold has a few; each one costs a row on every step the pair is near
MAX_WITNESSES = 16


class CollisionLimit(PairsMixin, TablesMixin, BroadPhaseMixin, MovingMixin, RowsMixin,
                     CopiesMixin, Limit):
    """Keep the robot ``margin`` away from ``obstacles`` and (``self_collision=True``) from
    itself, as one velocity-damper row per pair closer than ``influence``.

    Args:
        robot: a :class:`sjt_pin.Robot` (its ``collision_model``, else the ``<collision>``
            geometry of ``robot.urdf`` with ``robot.package_dirs``).
        obstacles: ``(coal shape, pin.SE3)`` pairs fixed in the world: ``coal.Sphere``, ``Box``,
            ``Capsule``, ``Cylinder``, ``Halfspace``, ``Plane``, ``Convex`` or a mesh
            (``BVHModel``; its convex hull with ``convex=True``). Move them with :meth:`move`,
            with their velocity when they move (the collision guide, "Moving obstacles").
        self_collision: also check the robot's link pairs, except adjacent links (geometries on
            the same joint or on a joint and its parent) and the pairs the SRDF disables.
        margin: distance to keep, m.
        influence: pairs farther than this (m) contribute no row; beside acceleration limits,
            farther as the arm's speed needs (module docstring, "Acceleration limits").
        gain: the damper's gain in (0, 1]: per period the excess ``d - margin`` may shrink by
            at most this fraction.
        pairs: extra ``(link_a, link_b)`` (or geometry names) to check although the rules above
            skip them (e.g. an adjacent pair).
        ignore: ``(link_a, link_b)`` (or geometry names; ``"world"`` for every obstacle) never
            to check.
        srdf: an SRDF path whose ``disable_collisions`` apply; by default the SRDF of an
            example-robot-data robot.
        convex: replace the robot's collision meshes and the mesh obstacles by their convex
            hulls (qhull, through coal). A hull contains its mesh, so the distance to it never
            exceeds the mesh's and the margin still holds for the mesh; GJK on hulls takes
            about a microsecond where a mesh-to-mesh distance takes from 10 us to several ms
            (Panda), and a hull's closest points move continuously where a mesh's jump from
            triangle to triangle (beside a mesh obstacle those jumps broke the acceleration
            limit 30x). A non-convex obstacle is filled in: the arm keeps off its hull
            (give its convex parts as obstacles of their own to reach into it). ``"robot"``
            replaces the robot's meshes only, keeping mesh obstacles as given (a bin the arm
            reaches into; an obstacle given as ``coal.Convex`` is convex either way).
            ``False`` keeps every mesh as given.
        witnesses: how many recent closest points of each pair within ``influence`` to keep as
            rows beside its own (module docstring, "Witnesses"); 0 keeps none.
    """

    name: str = "collision"
    uses_motion: bool = False  # its rows depend on q and dt (and, with acceleration limits,
    # on motion.dq and motion.ddq, which the solver then keeps up to date anyway)
    brakes_rows: bool = True  # (rows(): stoppable_rows, with its moving obstacles' speeds)

    def __init__(self, robot, obstacles: Sequence = (), self_collision: bool = False,
                 margin: float = 0.01, influence: float = 0.05, gain: float = 0.5,
                 pairs: Iterable[tuple[str, str]] = (), ignore: Iterable[tuple[str, str]] = (),
                 srdf: str | None = None, convex: bool | str = True, witnesses: int = 3):
        if coal is None:  # pragma: no cover
            raise CollisionError("CollisionLimit needs coal (shipped with the pin wheel)")
        settle_coal()
        for name, value in (("margin", margin), ("influence", influence), ("gain", gain)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer,
                                                                 np.floating)):
                raise TypeError(f"{name} must be a number, got {type(value).__name__}")
        if not (np.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be a finite distance >= 0 (m), got {margin!r}")
        if not (np.isfinite(influence) and influence > margin):
            raise ValueError(f"influence must be finite and > margin={margin} (m), "
                             f"got {influence!r}")
        if not (0 < gain <= 1):
            raise ValueError(f"gain must be in (0, 1], got {gain!r}")
        if isinstance(witnesses, bool) or not isinstance(witnesses, (int, np.integer)) or not (
                0 <= witnesses <= MAX_WITNESSES):
            raise ValueError(f"witnesses must be an int in [0, {MAX_WITNESSES}], got "
                             f"{witnesses!r}")
        if isinstance(convex, np.bool_):
            convex = bool(convex)
        if not (isinstance(convex, bool) or (isinstance(convex, str) and convex == "robot")):
            raise ValueError(f"convex must be True, False or 'robot', got {convex!r}")
        self.margin, self.influence, self.gain = float(margin), float(influence), float(gain)
        self.witnesses = int(witnesses)
        # what a copy in another process is rebuilt from (coal's hulls do not pickle)
        self._args = dict(robot=robot, obstacles=list(obstacles), self_collision=self_collision,
                          margin=margin, influence=influence, gain=gain, pairs=list(pairs),
                          ignore=list(ignore), srdf=srdf, convex=convex, witnesses=witnesses)
        self.model: pin.Model = robot.model
        self._mimics = list(getattr(robot, "mimic_joints", ()))
        self._mimic = mimic_map(robot.model, self._mimics)
        source = self.__dict__.pop("_restored_geometry", None)  # set by __setstate__
        self.geometry = source.copy() if source is not None else collision_model_of(robot)
        self._source = self.geometry.copy()  # the robot's own geometry (meshes), for copies
        if convex is not False:
            to_hulls(self.geometry)
        self._convex = convex is True  # (the mesh obstacles' hulls too)
        self.n_robot = self.geometry.ngeoms
        self._obstacle_ids: list[int] = []
        self._obstacle_shapes: list = []  # (as given: a mesh obstacle's hull is the limit's)
        for i, item in enumerate(obstacles):
            self._add_obstacle(i, item)
        #: each obstacle's velocity (m/s and rad/s, world axes: its origin's linear velocity,
        #: then its angular velocity), set by :meth:`move`
        self._velocity = np.zeros((len(self._obstacle_ids), 6))
        self._stamps: list = [None] * len(self._obstacle_ids)  # (time, pose) moved at (move)
        self._obstacle_of = np.full(self.geometry.ngeoms, -1, dtype=np.int64)  # (-1: robot's)
        self._obstacle_of[self._obstacle_ids] = np.arange(len(self._obstacle_ids))
        self._choose_pairs(self_collision, list(pairs), list(ignore),
                           srdf if srdf is not None else (srdf_of(robot) if self_collision
                                                          else None))
        self._data = self.model.createData()
        self._checked = False
        #: the pairs (indices into pairs / pair_names) of the first rows of the last rows()
        #: (one each, from its exact distance), and of the witness rows that follow them
        self.active: list[int] = []
        #: the pairs within influence at the last rows(): those of :attr:`active` and those
        #: whose row could not bind at the solver's speed limits (left out)
        self.within: list[int] = []
        self._witness_count = 0  # the witness rows of the last rows() (_owners holds their pairs)
        self._room: np.ndarray | None = None  # room() of the last rows()
        self._needs: np.ndarray | None = None  # needs() of the last rows()
        #: the robot's ranged joints (_retreat_speeds)
        self._ranges = PositionLimit(robot, np.ones(robot.model.nv), np.zeros(robot.model.nv))
        self._prepare_broad_phase()

    def bounds(self, kinematics, motion: Motion) -> tuple[np.ndarray, np.ndarray] | None:
        """Speed bounds (rad/s or m/s) that keep each step small against the damper: no
        joint moves a point of the geometry it carries by more than ``(influence - margin) /
        2`` in one period, so that the first-order rows hold (a correction of the stage that
        turns a joint by a radian in one step would carry a link through an obstacle before
        any row could see it) and no link crosses the band from beyond ``influence`` into
        ``margin`` between two steps. Far above a robot's own speeds at usual periods: 20 rad/s
        for a 1 m lever at 1 kHz with the defaults. On every step where the solver's speed
        limits (``motion.velocity_limits``) do not keep within them already (a free-flying
        base without a speed limit, a long period), never where they do; without speed limits
        (``solve()``'s iterations), while a pair is within ``influence``."""
        dt, speeds, known = motion.dt, motion.velocity_limits, self._bounds
        if known is None or known[1] is not speeds or known[0] != dt:
            cap = self.speed_caps(dt)
            lower = -cap
            lower.setflags(write=False)
            loose = speeds is not None and not bool(np.all(speeds <= cap))
            self._bounds = known = (dt, speeds, loose, (lower, cap))
        if speeds is not None:
            return known[3] if known[2] else None
        # no speed limits (solve()'s iterations): while a pair is within influence
        return known[3] if self.rows(kinematics, motion) is not None else None

    def speed_caps(self, dt: float) -> np.ndarray:
        """The speed bounds of :meth:`bounds` at period ``dt`` (s): ``(influence - margin) /
        (2 dt lever)`` (rad/s or m/s) for each joint with a lever (inf for the others;
        read-only). They bind only where the solver's own speed limits are loose, and there on
        every step, so a solver may hold them with its own."""
        if not dt > 0:
            raise ValueError(f"dt must be a period > 0 (s), got {dt!r}")
        with np.errstate(divide="ignore"):
            cap = np.where(self._lever > 0, (self.influence - self.margin)
                           / (2.0 * dt * self._lever), np.inf)
        cap.setflags(write=False)
        return cap

    # -- obstacles ---------------------------------------------------------------------------
    @property
    def obstacles(self) -> list[tuple]:
        """The obstacles as ``(coal shape, pin.SE3)`` pairs, at their current poses."""
        geoms = self.geometry.geometryObjects
        return [(shape, pin.SE3(geoms[g].placement))
                for shape, g in zip(self._obstacle_shapes, self._obstacle_ids, strict=True)]

    @property
    def velocities(self) -> np.ndarray:
        """The obstacles' velocities (nobstacles, 6) as :meth:`move` set them: linear (m/s)
        then angular (rad/s), world axes (a copy)."""
        return self._velocity.copy()

    # -- rows --------------------------------------------------------------------------------
    def rows(self, kinematics, motion: Motion) -> tuple[np.ndarray, np.ndarray] | None:
        """Rows ``A q_dot <= b`` (A: (k, nv) in m per unit of q_dot, b: (k,) in m/s) at the
        configuration of ``kinematics`` (after ``update(q)``: its joint poses and WORLD joint
        Jacobians), one for each pair within ``influence`` (:attr:`active`, then the witness
        rows) but those that no step within the solver's speed limits
        (``motion.velocity_limits``) can break (:meth:`_reach`; :attr:`within` lists them
        all); None when there is none. With acceleration limits in ``motion`` each bound is
        also cut to a closing speed they can stop within the pair's excess over ``margin``
        (module docstring, "Acceleration limits"), and every pair within influence has its
        row. A second call at the same configuration, period, obstacle poses and motion
        returns the same (read-only) arrays."""
        skip, q, listed = self._skip, kinematics.q, False
        # (most steps: nothing to query, as near_pairs finds; a moving obstacle queries)
        if skip is not None and q is not None and motion.acceleration_limits is None \
                and motion.dt > 0 and not self._moving:
            listed = near_pairs(q, skip, self._influence)
            if listed == []:
                if self.active or self.within:
                    self.active, self.within = [], []
                self._witness_count, self._room, self._needs = 0, None, None
                return None
            views, speeds = self._views, motion.velocity_limits
            if listed and views[0] is kinematics.data and self._reaches[0] is speeds \
                    and self._checked:  # (a step like the last: no check, views and reach)
                here = self._key(q, motion)
                cache = self._cached(views[0], here, motion)
                if cache is not None:
                    (self.active, self.within, self._witness_count, self._room,
                     self._needs) = cache[2]
                else:
                    out = self._queried(views, listed, self._influence, self._reaches[1],
                                        motion.dt)
                    self._room, self._needs = self._room_of(out), None
                    cache = self._cache = (views[0], here, (self.active, self.within,
                                                            self._witness_count, self._room,
                                                            None), out, self._limits_of(motion))
                return cache[3]
        data, dt = kinematics.data, motion.dt
        accelerations, jerks = motion.acceleration_limits, motion.jerk_limits
        key = self._key(q, motion)
        cache = None if q is None else self._cached(data, key, motion)
        if cache is not None:
            (self.active, self.within, self._witness_count, self._room,
             self._needs) = cache[2]
            return cache[3]
        if not dt > 0:
            raise ValueError(f"dt must be a period > 0 (s), got {dt!r}")
        if not self._checked:
            self._check(kinematics.model, data)
        influence = self._influence
        if accelerations is not None and self._pair_lever is not None:
            influence = self._braking_influence
            braking_reach(self._pair_lever, motion.dq, accelerations, jerks, dt, BRAKING_SHARE,
                          self.influence, self.margin, influence)
        if accelerations is None:
            speeds, reaches = motion.velocity_limits, self._reaches
            reach = reaches[1] if reaches[0] is speeds else self._reach(speeds)
        else:
            reach = None  # (the stoppable rows below are tighter than the damper's)
        if self._moving:  # (the rows of a pair bound its relative speed: _carried)
            influence = influence + self._pair_speed * self._lookahead(motion)
            if reach is not None:
                reach = reach + self._pair_speed
        out = self._rows(data, dt, q, influence, reach, listed)
        carried = self._carried(out)
        needs = None
        if out is not None and accelerations is not None:
            A, b = out
            b.setflags(write=True)  # (its own data: the rows' bounds, cut in place)
            if carried is not None:  # (what the margin needs where an obstacle outruns)
                needs = np.empty_like(b)
            stoppable_rows(A, b, motion.dq, motion.ddq, accelerations, jerks, self.gain / dt,
                           dt, BRAKING_SHARE, EASING_SLACK, None, None, carried,
                           None if carried is None else self._retreat_speeds(motion), needs)
            b.setflags(write=False)
            if needs is not None:
                if np.isnan(needs).all():
                    needs = None
                else:
                    needs.setflags(write=False)
        elif out is not None and carried is not None:
            b = out[1] + carried
            b.setflags(write=False)
            out = out[0], b
        self._room, self._needs = self._room_of(out), needs
        self._cache = (data, key, (self.active, self.within, self._witness_count, self._room,
                                   needs), out, self._limits_of(motion))
        return out

    def room(self) -> np.ndarray | None:
        """The room of each row of the last :meth:`rows` (k,): its pair's distance minus
        ``margin`` (m; a displacement ``d`` of the joints keeps the linearised distance at
        least ``margin`` where ``A d`` stays within it), None without rows."""
        return self._room

    def needs(self) -> np.ndarray | None:
        """For each row of the last :meth:`rows` given up, the bound the margin would need
        (:meth:`Limit.needs <sjt_pin.limits.Limit.needs>`; NaN for the others): beside
        acceleration limits, a row whose moving obstacle comes faster than the arm can retreat
        along it within its speed limits and ranges (``u > sum_j |A_ij| v_j``) counts the
        obstacle's approach only up to that retreat (``kernels.stoppable_rows``). None where
        no row is given up."""
        return self._needs

    def _room_of(self, out: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray | None:
        """The room of the rows ``out`` just made (:meth:`room`), from their pair rows."""
        if out is None:
            return None
        rows = self._pair_rows[:len(self.active) + self._witness_count]
        room = rows[:, 0] - rows[:, 1]
        room.setflags(write=False)
        return room

    @property
    def witness_pairs(self) -> list[int]:
        """The pairs (indices into :attr:`pairs`) of the witness rows of the last
        :meth:`rows`, which follow the rows of :attr:`active` (one each)."""
        return self._owners[:self._witness_count].astype(int).tolist()
