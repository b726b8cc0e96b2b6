"""The constraint stage's Python side: which limits a solver has, its user limits' bounds and
rows at each step, and what the compiled stage did, in names.

The stage itself is compiled (``sjt_pin/kernels/src/controller.hpp``): each joint's box from the
built-in limits (position with a braking distance, speed, acceleration, jerk), a user's bounds
and general rows ``A q_dot <= b``, and the projection (``projection.hpp``) that returns the
method's step where it is within every limit and else the admissible velocity nearest it in
the method's metric. This module gathers what the user's limits say at a step (each limit's
``bounds`` intersected, its ``rows`` stacked, each row's owner kept for
:attr:`StepInfo.active_rows <sjt_pin.StepInfo.active_rows>`; beside acceleration limits, the
rows with room of a limit that does not brake its own cut to closing speeds the arm can stop
within that room) and turns the compiled report's codes into ``(limit, joint)`` names.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import kernels
from .limits.base import BRAKING_SHARE, EASING_SLACK, Limit, Motion

_F64 = np.dtype(np.float64)
#: a velocity this close to a bound (rad/s, m/s) is on it (the compiled stage's own tolerance)
TOLERANCE = 1e-12
#: the names of the compiled stage's reasons for a bound (``bounds.hpp``'s ``Reason``); a user's
#: bound is named by its limit
REASONS = {1: "position", 2: "velocity", 3: "acceleration", 4: "jerk", 5: "braking"}
_USER, _FIXED = 6, 7


def as_rows(rows) -> tuple[np.ndarray, np.ndarray]:
    """A limit's rows ``(A, b)``, ``A q_dot <= b``, as the stage takes them: C-contiguous float64
    arrays, ``A`` (k, n) and ``b`` (k,) (one row may come as a vector; lists and integer arrays
    are converted); ``rows`` itself where its arrays are that already."""
    A, b = rows
    if (type(A) is np.ndarray and type(b) is np.ndarray and A.dtype == _F64 and b.dtype == _F64
            and A.ndim == 2 and b.ndim == 1 and A.flags.c_contiguous and b.flags.c_contiguous):
        return rows
    return (np.ascontiguousarray(np.atleast_2d(np.asarray(A, dtype=float))),
            np.ascontiguousarray(np.atleast_1d(np.asarray(b, dtype=float))))


class UserLimits:
    """A solver's limits beyond the built-in ones, evaluated at each step.

    Args:
        limits: the :class:`~sjt_pin.limits.Limit` objects.
        nv: the number of velocity coordinates.
    """

    def __init__(self, limits: Sequence[Limit], nv: int):
        self.limits = list(limits)
        for limit in self.limits:
            if not isinstance(limit, Limit):
                raise TypeError(f"limits must hold sjt_pin Limit objects, got {limit!r}")
        self.nv = nv
        self._lower, self._upper = np.empty(nv), np.empty(nv)
        self._lower_by = np.full(nv, -1, dtype=np.int64)
        self._upper_by = np.full(nv, -1, dtype=np.int64)
        #: the limits whose bounds are only their speed caps (held with the speed limits)
        self.capped: set[int] = set()
        #: the last evaluation's rows ``(A, b, owners)`` (None without rows)
        self.last_rows: tuple[np.ndarray, np.ndarray, list[str]] | None = None
        #: what the last evaluation's rows need (k,; :meth:`Limit.needs
        #: <sjt_pin.limits.Limit.needs>`, NaN for a row whose bound is what it needs), None
        #: where no row is given up
        self.needs: np.ndarray | None = None
        #: the room (k,) the last evaluation's rows leave a displacement (:meth:`Limit.room
        #: <sjt_pin.limits.Limit.room>`; NaN for rows that bound velocity only), None where no
        #: limit gives one
        self.room: np.ndarray | None = None
        #: which of the last evaluation's rows have bounds their limit made a damper of their
        #: room (k,; 1, e.g. a collision limit's) and which the stage braked to their room
        #: itself (0: a bound that may say nothing of the room, such as a speed cap), None
        #: where the stage braked none
        self.dampers: np.ndarray | None = None
        self._blocks: list[tuple[Limit, np.ndarray, np.ndarray]] = []
        # per limit: whether it has bounds of its own (the base class's say nothing, and are
        # not called each step); whether any limit has a room of its own (the same)
        self._plan = [(k, limit, type(limit).bounds is not Limit.bounds)
                      for k, limit in enumerate(self.limits)]
        self._any_room = any(type(limit).room is not Limit.room for limit in self.limits)
        # whether any limit with a room of its own leaves its rows' braking to the stage
        self._braked_here = any(type(limit).room is not Limit.room and not limit.brakes_rows
                                for limit in self.limits)
        # whether some limit brakes its own rows (else every row with room is the stage's)
        self._some_brake = any(limit.brakes_rows for limit in self.limits)
        self._zeros = np.zeros(0)
        self._any_needs = any(type(limit).needs is not Limit.needs for limit in self.limits)

    def evaluate(self, kinematics, motion: Motion):
        """``(lower, upper, A, b, owners)`` at this step: the intersection of the limits'
        bounds (``None``, ``None`` when none bounds), their rows stacked (``None``, ``None``
        when none applies; ``b`` braked to the rows' room, :meth:`_braked`, where the stage
        brakes them: :attr:`last_rows` keeps them as asked) and each row's limit name."""
        n = self.nv
        lower = upper = A = b = None
        blocks: list[tuple[Limit, np.ndarray, np.ndarray]] = []
        owners: list[str] = []
        for k, limit, bounded in self._plan:
            if bounded and k not in self.capped:
                bounds = limit.bounds(kinematics, motion)
                if bounds is not None:
                    lo, hi = _checked_bounds(limit, bounds, n)
                    if lower is None:
                        lower, upper = self._lower, self._upper
                        lower[:], upper[:] = -np.inf, np.inf
                        self._lower_by[:], self._upper_by[:] = -1, -1
                    tighter = lo > lower
                    lower[tighter], self._lower_by[tighter] = lo[tighter], k
                    tighter = hi < upper
                    assert upper is not None  # (set with lower)
                    upper[tighter], self._upper_by[tighter] = hi[tighter], k
            rows = limit.rows(kinematics, motion)
            if rows is not None:
                Ak, bk = as_rows(rows)
                if Ak.shape != (bk.size, n):
                    raise ValueError(f"{limit!r}.rows() must return A of shape (k, {n}) and b "
                                     f"of shape (k,), got {Ak.shape} and {bk.shape}")
                # (NaN or inf in A, NaN in b: the compiled stage refuses them, and
                # raise_non_finite_rows names the limit)
                blocks.append((limit, Ak, bk))
                owners += [limit.name] * bk.size
        room = asked = dampers = None
        if blocks:
            if len(blocks) == 1:
                _, A, b = blocks[0]
            else:
                A = np.vstack([a for _, a, _ in blocks])
                b = np.concatenate([c for _, _, c in blocks])
            room = self._stacked(blocks, "room") if self._any_room else None
            asked = b
            self.needs = self._stacked(blocks, "needs") if self._any_needs else None
            if room is not None and self._braked_here and motion.acceleration_limits is not None:
                b, dampers = self._braked(blocks, A, b, room, self.needs, motion)
        else:
            self.needs = None
        self.room, self.dampers = room, dampers
        self._blocks = blocks
        # (the rows as their limits ask them: what rows_exceeded measures a step against)
        self.last_rows = None if A is None or asked is None else (A, asked, owners)
        return lower, upper, A, b, owners

    def _braked(self, blocks: list[tuple[Limit, np.ndarray, np.ndarray]], A: np.ndarray,
                b: np.ndarray, room: np.ndarray, needs: np.ndarray | None, motion: Motion
                ) -> tuple[np.ndarray, np.ndarray | None]:
        """The rows' bounds ``b`` with each row that has a room, is not given up (NaN in
        ``needs``) and whose limit does not brake its own rows
        (:attr:`Limit.brakes_rows <sjt_pin.limits.Limit.brakes_rows>`) lowered to
        closing speeds the arm stops within that room at half its acceleration (and jerk)
        limits, never asked to slow faster than they allow (``kernels.stoppable_rows``): a
        new array (the limits' own are not written); and :attr:`dampers` (None where no row
        was braked here)."""
        if not self._some_brake and needs is None:  # (every row's: no mask to make)
            if self._zeros.size != b.size:
                self._zeros = np.zeros(b.size)
            own, mine = self._zeros, room
        else:
            own = np.concatenate([np.full(bk.size, 1.0 if limit.brakes_rows else 0.0)
                                  for limit, _, bk in blocks])
            mine = np.where((own == 0.0) & (True if needs is None else np.isnan(needs)), room,
                            np.nan)
            if not np.isfinite(mine).any():
                return b, None
        b = np.array(b, dtype=float)
        kernels.stoppable_rows(A, b, motion.dq, motion.ddq, motion.acceleration_limits,
                               motion.jerk_limits, 1.0 / motion.dt, motion.dt, BRAKING_SHARE,
                               EASING_SLACK, room=mine)
        return b, own

    @staticmethod
    def _stacked(blocks: list[tuple[Limit, np.ndarray, np.ndarray]], name: str
                 ) -> np.ndarray | None:
        """The rows' values of each limit's method ``name`` (``room`` or ``needs``) stacked,
        NaN for a limit without them; None where no limit has any."""
        parts = []
        for limit, _, bk in blocks:
            values = getattr(limit, name)()
            if values is not None:
                values = np.ascontiguousarray(values, dtype=float)
                if values.shape != bk.shape:
                    raise ValueError(f"{limit!r}.{name}() must return one value per row of "
                                     f"its rows(), shape {bk.shape}, got {values.shape}")
            parts.append(values)
        if all(values is None for values in parts):
            return None
        if len(parts) == 1:
            return parts[0]
        return np.concatenate([np.full(bk.size, np.nan) if values is None else values
                               for values, (_, _, bk) in zip(parts, blocks, strict=True)])

    def raise_non_finite_rows(self) -> None:
        """ValueError naming the limit whose last rows hold NaN or inf in ``A`` or NaN in
        ``b``, if one does (a row that bounds nothing would let the joints move freely)."""
        for limit, A, b in self._blocks:
            if not (np.all(np.isfinite(A)) and not np.any(np.isnan(b))):
                raise ValueError(f"{limit!r}.rows() returned NaN or inf in A or NaN in b: a "
                                 "row that bounds nothing would let the joints move freely")

    def exceeded(self, dq: np.ndarray, tol: float = 1e-9) -> tuple[tuple[str, float], ...]:
        """The limits whose rows of the last evaluation ``dq`` does not keep, each with the
        largest excess ``A_i dq - b_i`` of its rows (their units: m/s for the collision
        limit's; ``b`` as the limit needs it, :meth:`Limit.needs
        <sjt_pin.limits.Limit.needs>`), in the order of the limits; ``()`` where every row
        holds (to ``tol`` times the row's scale)."""
        if self.last_rows is None:
            return ()
        A, b, owners = self.last_rows
        if self.needs is not None:
            b = np.where(np.isnan(self.needs), b, self.needs)
        excess = A @ dq - b
        scale = 1.0 + np.abs(A) @ np.abs(dq) + np.abs(b)
        out: dict[str, float] = {}
        for i in np.flatnonzero(excess > tol * scale):
            out[owners[i]] = max(out.get(owners[i], 0.0), float(excess[i]))
        return tuple(out.items())

    def bound_owner(self, joint: int, upper: bool) -> str:
        """The name of the user's limit whose bound of ``joint`` the last evaluation kept."""
        k = int((self._upper_by if upper else self._lower_by)[joint])
        return self.limits[k].name if k >= 0 else "limit"

    def admits_rest(self, kinematics, motion: Motion, tol: float = 1e-9) -> bool:
        """Whether standing still (``q_dot = 0``) meets every limit: the configuration is
        within them."""
        lower, upper, A, b, _ = self.evaluate(kinematics, motion)
        if lower is not None and (np.any(lower > tol) or np.any(upper < -tol)):
            return False
        return b is None or bool(np.all(b >= -tol))

    def project(self, dq: np.ndarray, Jw: np.ndarray, kinematics, motion: Motion) -> np.ndarray:
        """``dq`` (rad/s) moved onto every limit's bounds and rows by the smallest change in the
        metric ``Jw^T Jw + rho I`` of the task rows ``Jw`` (rho: 1e-3 of that matrix's mean
        diagonal), or ``dq`` itself where it already meets them: ``solve()``'s displacements."""
        lower, upper, A, b, _ = self.evaluate(kinematics, motion)
        n = self.nv
        lo = np.full(n, -np.inf) if lower is None else lower.copy()
        hi = np.full(n, np.inf) if upper is None else upper.copy()
        A = np.zeros((0, n)) if A is None else A
        b = np.zeros(0) if b is None else b
        if (np.all(dq >= lo - TOLERANCE) and np.all(dq <= hi + TOLERANCE)
                and np.all(A @ dq <= b + TOLERANCE * (1.0 + np.abs(b)))):
            return dq
        rho = 1e-3 * max(float(np.einsum("ij,ij->", Jw, Jw)) / n, 1e-12)
        x, _, _ = kernels.project(np.asarray(dq, dtype=float), np.full(n, rho),
                                  np.ascontiguousarray(Jw, dtype=float), lo, hi, A, b,
                                  np.zeros((0, n)), np.zeros(0))
        return x


def _checked_bounds(limit: Limit, bounds, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A limit's ``bounds()`` as float arrays of shape (n,): a wrong shape or a NaN (a bound
    that bounds nothing) raises ``ValueError`` naming the limit."""
    lower, upper = (np.asarray(x, dtype=float) for x in bounds)
    if (lower.shape != (n,) or upper.shape != (n,) or math.isnan(float(lower.sum()))
            or math.isnan(float(upper.sum()))):
        raise ValueError(f"{limit!r}.bounds() must return (lower, upper) of shape ({n},) "
                         "without NaN (inf: no bound)")
    return lower, upper


def active_limits(controller, joint_names: Sequence[str], user: UserLimits | None,
                  speed_by: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """``(limit, joint)`` for each joint the stage held on a bound (its velocity on the bound
    and different from the method's; where the arm rests short of a step too small to make,
    that step's): from the compiled report's reasons. ``speed_by`` names the limit behind
    each joint's speed bound (``"velocity"``, or a user limit's speed caps)."""
    x, desired = controller.holding, controller.desired
    lower, upper = controller.lower, controller.upper
    lower_by, upper_by = controller.lower_by, controller.upper_by
    pairs: list[tuple[str, str]] = []
    moved = np.abs(x - desired) > TOLERANCE * (1.0 + np.abs(desired))
    for j in np.flatnonzero(moved):
        for at, code, is_upper in ((x[j] >= upper[j] - TOLERANCE, int(upper_by[j]), True),
                                   (x[j] <= lower[j] + TOLERANCE, int(lower_by[j]), False)):
            if not at or code in (0, _FIXED):
                continue
            if code == _USER:
                name = user.bound_owner(int(j), is_upper) if user is not None else "limit"
            elif code == 2:
                name = speed_by[int(j)]
            else:
                name = REASONS[code]
            pair = (name, joint_names[int(j)])
            if pair not in pairs:
                pairs.append(pair)
    return tuple(pairs)
