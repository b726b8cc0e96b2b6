"""The constraint stage: every limit's inequalities on the joint velocity, enforced after the
method, for every method.

A step's method proposes a joint velocity ``q_dot* = M (x_dot_d + K e)``. Each limit
(:mod:`sjt_pin.limits`) bounds the joint velocity of this step — box rows
``lower <= q_dot <= upper`` or general rows ``A q_dot <= b``. The stage returns the admissible
velocity closest to what the method wants, in the method's own terms:

1. **Box rows** by *Saturation in the Null Space* (SNS; Flacco, De Luca and Khatib, "Control of
   redundant robots under hard joint constraints: Saturation in the Null Space", IEEE T-RO
   31(3), 2015): the joint that limits the task most is held at its bound, and the method is
   solved again on the other joints for the task velocity the held ones leave to them — the
   same mapping M on fewer columns, so SJT keeps its scaling D. When no set of held joints can
   meet the whole task, the task velocity is scaled down, ``s (x_dot_d + K e)`` with the
   largest ``s`` in [0, 1] that the bounds allow: the motion keeps its direction, slower,
   never distorted. Each round costs one or two solves of the method.
2. **General rows** (collision dampers, workspace bounds) that the result still breaks: the
   smallest correction in the metric ``J_w^T J_w + rho I`` — changes of the task motion cost
   much, self-motion little, so the other joints take over — subject to every row and bound,
   a small convex QP solved exactly on its dual by an active-set method. When the box cut the
   method's velocity, the correction starts from that velocity scaled as a whole into the box
   (SNS's first candidate, :func:`scaled_into`), not from SNS's result: which joints SNS holds
   can flip with ``q``, and the two corrections with it (a blocked arm cycling between them).

The box of each joint is the intersection of every limit's bounds. *Hard* limits (positions,
speeds, collisions) win over *smoothness* limits (acceleration, jerk) when both cannot hold —
a start outside the range, limits changed between steps: the velocity is then the point of the
hard box nearest the smoothness box, and the step reports it.

A solver with a built-in method runs this stage on the built-in limits (position, speed,
acceleration, jerk) inside its step kernel (``smooth_stage_c`` in ``kernels/src/smooth_stage.c``); a
user's limits then correct that step only where it breaks them (``kernels.rows_step``,
``kernels.smooth_rows_step``), and a user's bound that the hard box does not meet leaves the
step to this module. This module is the compiled stage's reference
(``sjt_pin.solver.COMPILED_SMOOTH_STAGE = False`` runs it on every step), and
``tests/test_smooth_kernel.py`` holds the two equal.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from . import kernels
from .kernels import BOUND_TOL, project_rows
from .limits.base import Limit, Motion

#: ``solve(free, held)``: the method's joint velocity (nv,; rad/s) with only the ``free``
#: joints moving and the others at ``held`` (nv,): the task velocity the held ones produce is
#: taken off the free joints' share. ``solve(free, None)`` leaves the held joints at rest.
Solve = Callable[[np.ndarray, np.ndarray | None], np.ndarray]

#: a bound counts as reached within this many rad/s (m/s) of it (the kernels' BOUND_TOL)
TOLERANCE = BOUND_TOL
_F64 = np.dtype(np.float64)


@dataclass
class Bounds:
    """Per-joint bounds on q_dot (rad/s, m/s) and, for each, the index of the limit that set
    it (-1: none)."""

    lower: np.ndarray
    upper: np.ndarray
    lower_by: np.ndarray
    upper_by: np.ndarray


@dataclass
class Box:
    """The bounds of one step: the hard limits' (positions, speeds, ...) and the smoothness
    limits' (acceleration, jerk; ``None`` when the solver has none)."""

    hard: Bounds
    smooth: Bounds | None = None
    #: bool (nv,): joints whose smoothness limits contradicted each other (one yielded)
    contradicted: np.ndarray | None = None

    @property
    def lower(self) -> np.ndarray:
        return self.hard.lower

    @property
    def upper(self) -> np.ndarray:
        return self.hard.upper


@dataclass
class Outcome:
    """What the stage did to one step's joint velocity."""

    dq: np.ndarray
    scale: float = 1.0  # the task scale s (1: the whole task)
    held: np.ndarray | None = None  # bool (nv,): joints held at a bound
    active: tuple[tuple[str, str], ...] = ()  # (limit, joint) pairs at their bound
    rows: tuple[str, ...] = ()  # limits whose general rows were active
    conflict: tuple[str, ...] = ()  # joints whose acceleration/jerk limit yielded


class ConstraintStage:
    """The limits of one solver and the stage that enforces them (see the module docstring).

    Args:
        limits: the :class:`~sjt_pin.limits.Limit` objects.
        moving: (nv,) bool, the joints the solver moves (the others keep ``q_dot = 0``).
        names: the name of each velocity coordinate's joint (for reports).
        task_rows: how many of the stacked rows are the tasks' (the posture rows that may
            follow are not a task the stage keeps).
    """

    def __init__(self, limits: Sequence[Limit], moving: np.ndarray, names: Sequence[str],
                 task_rows: int):
        self.task_rows = task_rows
        self.limits = list(limits)
        self.moving = np.asarray(moving, dtype=bool)
        self.names = list(names)
        self.nv = self.moving.size

    # -- the box ---------------------------------------------------------------------------
    def box(self, kinematics, motion: Motion) -> Box | None:
        """The intersections of the hard limits' bounds and of the smoothness limits' bounds at
        this step, or ``None`` if no limit bounds."""
        n = self.nv
        parts = {}
        for k, limit in enumerate(self.limits):
            bounds = _checked(limit, limit.bounds(kinematics, motion), n)
            if bounds is None:
                continue
            if limit.hard not in parts:
                parts[limit.hard] = [np.full(n, -np.inf), np.full(n, np.inf), np.full(n, -1),
                                     np.full(n, -1)]
            lo_t, hi_t, lo_by, hi_by = parts[limit.hard]
            lo, hi = bounds
            tighter = lo > lo_t
            lo_t[tighter], lo_by[tighter] = lo[tighter], k
            tighter = hi < hi_t
            hi_t[tighter], hi_by[tighter] = hi[tighter], k
        if not parts:
            return None
        lower, upper, lower_by, upper_by = parts.get(True) or [
            np.full(n, -np.inf), np.full(n, np.inf), np.full(n, -1), np.full(n, -1)]
        # joints the solver does not move stay at rest
        still = ~self.moving
        lower[still], upper[still] = np.minimum(lower[still], 0.0), np.maximum(upper[still], 0.0)
        box = Box(Bounds(lower, upper, lower_by, upper_by))
        if False in parts:
            smooth_box = box.smooth = Bounds(*parts[False])
            # smoothness limits that contradict each other: the bound of the one that does not
            # yield first (Limit.yields_first), else the middle of their bounds
            torn = smooth_box.lower > smooth_box.upper
            if torn.any():
                firm = np.array([not limit.yields_first for limit in self.limits] + [False])
                lo_firm, hi_firm = firm[smooth_box.lower_by], firm[smooth_box.upper_by]
                middle = 0.5 * (smooth_box.lower + smooth_box.upper)
                point = np.where(lo_firm & ~hi_firm, smooth_box.lower,
                                 np.where(hi_firm & ~lo_firm, smooth_box.upper, middle))
                smooth_box.lower[torn] = smooth_box.upper[torn] = point[torn]
                box.contradicted = torn
        return box

    def general_rows(self, kinematics, motion: Motion, check: bool = True):
        """Every limit's general rows: ``(A, b, owners)`` or ``None``; ``check=False`` leaves
        the test for NaN to a compiled caller (``kernels.rows_step`` checks them itself)."""
        blocks, owners = [], []
        for limit in self.limits:
            rows = limit.rows(kinematics, motion)
            if rows is None:
                continue
            A, b = as_rows(rows)
            if A.shape != (b.size, self.nv):
                raise ValueError(f"{limit!r}.rows() must return A of shape (k, {self.nv}) and "
                                 f"b of shape (k,), got {A.shape} and {b.shape}")
            if check and (not math.isfinite(float(A.sum())) or math.isnan(float(b.sum()))):
                raise ValueError(f"{limit!r}.rows() returned NaN or inf in A or NaN in b: a row "
                                 "that bounds nothing would let the joints move freely")
            blocks.append((A, b))
            owners += [limit.name] * b.size
        if not blocks:
            return None
        if len(blocks) == 1:
            return blocks[0][0], blocks[0][1], owners
        return np.vstack([a for a, _ in blocks]), np.concatenate([b for _, b in blocks]), owners

    def hard_parts(self, kinematics, motion: Motion):
        """This stage's bounds and rows at this step, for a step that the solver's kernel
        checks and corrects itself (``kernels.rows_step``): ``(lower, upper, rows)`` with the
        intersection of the limits' bounds (rad/s; ``None`` when none bounds) and
        :meth:`general_rows`; ``None`` when a smoothness limit bounds the step (only
        :meth:`enforce` weighs those)."""
        lower = upper = None
        for limit in self.limits:  # (the kernels check the bounds and rows for NaN)
            bounds = limit.bounds(kinematics, motion)
            if bounds is None:
                continue
            if not limit.hard:
                return None
            if lower is None or upper is None:
                lower, upper = bounds
            else:
                lower, upper = np.maximum(lower, bounds[0]), np.minimum(upper, bounds[1])
        return lower, upper, self.general_rows(kinematics, motion, check=False)

    def check(self, kinematics, motion: Motion) -> None:
        """Raise the ``ValueError`` that names the limit whose bounds or rows are broken
        (NaN, wrong shape) at this step, if any (after a compiled check refused them)."""
        self.box(kinematics, motion)
        self.general_rows(kinematics, motion)

    # -- enforcing ---------------------------------------------------------------------------
    def enforce(self, dq: np.ndarray, solve: Solve, kinematics, motion: Motion,
                metric: Callable[[], np.ndarray] | None = None) -> Outcome:
        """The admissible joint velocity closest to the method's ``dq`` (rad/s; see the module
        docstring). ``solve`` re-solves the method on a subset of joints; ``metric()`` gives
        ``J_w`` (m, nv) for the general rows' correction (only called when a row is broken)."""
        box = self.box(kinematics, motion)
        rows = self.general_rows(kinematics, motion)
        rows_w: list[np.ndarray] = []

        def weighted():
            if not rows_w:
                rows_w.append(metric() if metric is not None else np.zeros((0, self.nv)))
            return rows_w[0]

        outcome = Outcome(dq)
        desired = None
        cut = False  # whether the box cut dq
        if box is not None and not _inside(dq, box.lower, box.upper):
            cut = True
            outcome = saturate(dq, solve, box.lower, box.upper, self.moving,
                               lambda: weighted()[:self.task_rows])
        if box is not None and box.smooth is not None:
            soft = box.smooth
            for limit in self.limits:  # reach the wanted velocity without overshooting it
                approach = getattr(limit, "approach", None)
                if approach is not None:
                    lo, hi = approach(outcome.dq, motion)
                    np.maximum(soft.lower, np.minimum(lo, soft.upper), out=soft.lower)
                    np.minimum(soft.upper, np.maximum(hi, soft.lower), out=soft.upper)
            desired = outcome.dq
            outcome.dq, torn = smooth(outcome.dq, box.hard, soft)
            if box.contradicted is not None:
                torn = torn | box.contradicted
            outcome.conflict = tuple(self.names[j] for j in np.flatnonzero(torn))
        if rows is not None:
            A, b, owners = rows
            slack = A @ outcome.dq - b
            if np.any(slack > TOLERANCE * (1.0 + np.abs(b))):
                lower = box.lower if box is not None else np.full(self.nv, -np.inf)
                upper = box.upper if box is not None else np.full(self.nv, np.inf)
                start = outcome.dq  # without a smoothness box, when the box cut dq: the
                # method's dq scaled into it (continuous in dq, where SNS is not: scaled_into)
                if cut and box is not None and box.smooth is None:
                    # (what the step reports follows: that scale, no joint held)
                    start, outcome.scale = scaled_into(dq, box.lower, box.upper, self.moving)
                    outcome.held = None
                outcome.dq = project(start, weighted(), A, b, lower, upper, self.moving)
                slack = A @ outcome.dq - b
            tight = slack > -1e-9 * (1.0 + np.abs(b))
            outcome.rows = tuple(sorted({owners[i] for i in np.flatnonzero(tight)}))
        if box is not None:
            outcome.active = active_limits(outcome.dq, box, [x.name for x in self.limits],
                                           self.names, desired)
        return outcome

    def user_limits(self) -> ConstraintStage | None:
        """A stage of the limits beyond the built-in ones (position, velocity, acceleration,
        jerk), or ``None`` if there are none: what ``solve()`` must honour besides the URDF."""
        from .limits import AccelerationLimit, JerkLimit, PositionLimit, VelocityLimit

        builtin = (AccelerationLimit, JerkLimit, PositionLimit, VelocityLimit)
        user = [limit for limit in self.limits if type(limit) not in builtin]
        if not user:
            return None
        return ConstraintStage(user, self.moving, self.names, self.task_rows)

    def admits(self, dq: np.ndarray, kinematics, motion: Motion) -> bool:
        """Whether ``dq`` meets every limit's bounds and rows."""
        box = self.box(kinematics, motion)
        if box is not None and not _inside(dq, box.lower, box.upper):
            return False
        rows = self.general_rows(kinematics, motion)
        return rows is None or bool(np.all(rows[0] @ dq <= rows[1] + TOLERANCE
                                           * (1.0 + np.abs(rows[1]))))

    def admits_rest(self, kinematics, motion: Motion, tol: float = 1e-9) -> bool:
        """Whether standing still (``q_dot = 0``) meets every limit: the configuration is
        within them."""
        box = self.box(kinematics, motion)
        if box is not None and (np.any(box.lower > tol) or np.any(box.upper < -tol)):
            return False
        rows = self.general_rows(kinematics, motion)
        return rows is None or bool(np.all(rows[1] >= -tol))

    def project(self, dq: np.ndarray, Jw: np.ndarray, kinematics, motion: Motion) -> np.ndarray:
        """``dq`` moved onto every limit's bounds and rows by the smallest change in the
        metric of the task rows ``Jw`` (:func:`project`), or ``dq`` if it already meets them."""
        box = self.box(kinematics, motion)
        rows = self.general_rows(kinematics, motion)
        lower = box.lower if box is not None else np.full(self.nv, -np.inf)
        upper = box.upper if box is not None else np.full(self.nv, np.inf)
        A, b = (rows[0], rows[1]) if rows is not None else (np.zeros((0, self.nv)), np.zeros(0))
        if _inside(dq, lower, upper) and np.all(A @ dq <= b + TOLERANCE * (1 + np.abs(b))):
            return dq
        return project(dq, Jw, A, b, lower, upper, self.moving)


def as_rows(rows) -> tuple[np.ndarray, np.ndarray]:
    """A limit's rows ``(A, b)``, ``A q_dot <= b``, as the stage takes them: float64 arrays,
    ``A`` (k, n) and ``b`` (k,) (one row may come as a vector; lists and integer arrays are
    converted); ``rows`` itself where its arrays are that already."""
    A, b = rows
    if type(A) is np.ndarray and type(b) is np.ndarray and A.dtype == _F64 \
            and b.dtype == _F64 and A.ndim == 2 and b.ndim == 1:
        return rows
    return np.atleast_2d(np.asarray(A, dtype=float)), np.atleast_1d(np.asarray(b, dtype=float))


def active_limits(dq: np.ndarray, box: Box, limit_names: Mapping[int, str] | Sequence[str],
                  joint_names: Sequence[str],
                  desired: np.ndarray | None = None) -> tuple[tuple[str, str], ...]:
    """(limit name, joint name) for each joint of ``dq`` (rad/s) at one of its bounds, the hard
    box's first: ``limit_names[k]`` names the limit ``k`` of the boxes' ``*_by`` indices. A
    smoothness bound counts only where it cut the velocity the smoothing started from,
    ``desired`` (a bound that merely contains a velocity, such as the narrow jerk bounds
    around an arm at rest, is not active)."""
    pairs = []
    for bounds in (box.hard, box.smooth):
        if bounds is None:
            continue
        lower, upper, lower_by, upper_by = (bounds.lower, bounds.upper, bounds.lower_by,
                                            bounds.upper_by)
        at_lower = (dq <= lower + TOLERANCE) & (lower_by >= 0)
        at_upper = (dq >= upper - TOLERANCE) & (upper_by >= 0)
        if bounds is box.smooth and desired is not None:
            cut = np.abs(dq - desired) > TOLERANCE
            at_lower &= cut
            at_upper &= cut
        for j in np.flatnonzero(at_lower | at_upper):
            k = upper_by[j] if at_upper[j] else lower_by[j]
            pair = (limit_names[int(k)], joint_names[int(j)])
            if pair not in pairs:
                pairs.append(pair)
    return tuple(pairs)


def _checked(limit: Limit, bounds, n: int):
    """A limit's ``bounds()`` (``None`` or ``(lower, upper)``, each (n,)), checked: a wrong shape
    or a NaN (a bound that bounds nothing) raises ``ValueError`` naming the limit."""
    if bounds is None:
        return None
    lower, upper = bounds
    if (np.shape(lower) != (n,) or np.shape(upper) != (n,)
            or math.isnan(float(np.sum(lower))) or math.isnan(float(np.sum(upper)))):
        raise ValueError(f"{limit!r}.bounds() must return (lower, upper) of shape ({n},) "
                         "without NaN (inf: no bound)")
    return bounds


def _inside(dq, lower, upper) -> bool:
    return bool(np.all(dq >= lower - TOLERANCE) and np.all(dq <= upper + TOLERANCE))


def task_scale(a: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray,
               free: np.ndarray) -> tuple[float, int]:
    """The largest ``s`` in [0, 1] with ``lower <= b + s a <= upper`` on the ``free`` joints,
    and the joint that limits it (-1 when s = 1 fits); ``s = -1`` when no ``s`` in [0, 1]
    fits (the held joints alone already push a free one out of its box)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        top = np.where(a > 0, (upper - b) / a, np.where(a < 0, (lower - b) / a, np.inf))
        bottom = np.where(a > 0, (lower - b) / a, np.where(a < 0, (upper - b) / a, -np.inf))
    still_out = (a == 0) & ((b < lower - TOLERANCE) | (b > upper + TOLERANCE))
    top = np.where(free & ~still_out, top, np.where(free, -np.inf, np.inf))
    bottom = np.where(free, bottom, -np.inf)
    k = int(np.argmin(top))
    s_max, s_min = float(top[k]), float(np.max(bottom, initial=-np.inf))
    if s_max >= 1.0 and s_min <= 1.0:
        return 1.0, -1
    if s_max < 0.0 or s_min > min(s_max, 1.0) + 1e-12:
        return -1.0, k
    return max(min(s_max, 1.0), 0.0), k


#: the ridge of the stage's dual QP, relative to its largest diagonal entry (see
#: :func:`nonnegative_qp`)
DUAL_RIDGE = kernels.DUAL_RIDGE
#: :func:`rest_target`'s ridge of ``Jw Jw^T``, relative to its mean diagonal entry
REST_RIDGE = 1e-12

#: the free joints still span the task space while the smallest singular value of their
#: normalised task columns is above this fraction of their root-sum-square (of the largest,
#: within a factor sqrt(m); Flacco's rank test, the compiled kernels' test)
RANK_TOL = kernels.RANK_TOL


def scaled_into(dq: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                moving: np.ndarray) -> tuple[np.ndarray, float]:
    """The method's ``dq`` (rad/s) scaled down as a whole into the box ``[lower, upper]``
    (the nearest point of the box when no scale fits), and that scale s in [0, 1]:
    :func:`saturate`'s first candidate, and
    what the general rows correct when the box cut ``dq`` (:meth:`ConstraintStage.enforce`).
    It is continuous in ``dq``; SNS's result is not, where two sets of held joints scale the
    task alike and the choice between them flips with ``q``: projected onto the rows, each
    gives a different step, and a blocked arm cycles between them with its hand still."""
    s, _ = task_scale(dq, np.zeros(dq.size), lower, upper, moving)
    s = max(s, 0.0)
    out = np.clip(s * dq, lower, upper)
    out[~moving] = 0.0
    return out, s


def saturate(dq: np.ndarray, solve: Solve, lower: np.ndarray, upper: np.ndarray,
             moving: np.ndarray, rows: Callable[[], np.ndarray]) -> Outcome:
    """Saturation in the Null Space on the box ``[lower, upper]`` (module docstring, step 1).

    ``rows()`` gives the tasks' weighted rows (without posture rows). The first candidate is
    the method's own ``dq`` scaled down as a whole, which keeps the task direction exactly;
    each round of SNS adds a candidate — the held joints at their bounds, the others solved
    again and the task scaled — as long as the free joints still span the task space (their
    task columns, normalised, have full row rank within :data:`RANK_TOL`): with fewer, the
    method would distort the task instead of keeping it, and holding more joints cannot help.
    The largest scale wins.
    """
    n = dq.size
    free = moving.copy()
    held = np.zeros(n, dtype=bool)
    held_velocity = np.zeros(n)
    s, _ = task_scale(dq, np.zeros(n), lower, upper, free)
    best = (s, dq, np.zeros(n), held.copy(), held_velocity.copy())
    a, b = dq, np.zeros(n)
    J = None
    for _ in range(n):
        s, k = task_scale(a, b, lower, upper, free)
        if held.any():
            J = rows() if J is None else J
            if not _spans(J[:, free]):
                break  # the free joints no longer make the task: nor will fewer
        if s > best[0]:
            best = (s, a, b, held.copy(), held_velocity.copy())
        if s >= 1.0 or k < 0:
            break
        # hold the joint that limits the task at the bound it reaches first
        direction = a[k] if a[k] != 0.0 else (b[k] - upper[k] if b[k] > upper[k] else b[k])
        held[k], free[k] = True, False
        held_velocity[k] = upper[k] if direction > 0 else lower[k]
        if not free.any():
            break
        a = solve(free, None)
        b = solve(free, held_velocity) - a
    s, a, b, held, held_velocity = best
    out = np.where(held, held_velocity, b + max(s, 0.0) * a)
    out[~moving] = 0.0
    # when no scale fitted (s = -1), the nearest point of the box
    np.clip(out, lower, upper, out=out)
    return Outcome(out, max(s, 0.0), held)


def _spans(J: np.ndarray) -> bool:
    """Whether the columns of ``J`` (m, k), each scaled to unit norm, span R^m."""
    m, k = J.shape
    if k < m:
        return False
    norms = np.linalg.norm(J, axis=0)
    Jn = J[:, norms > 0] / norms[norms > 0]
    if Jn.shape[1] < m:
        return False
    sv = np.linalg.svd(Jn, compute_uv=False)
    # lambda_min(Jn Jn^T) > RANK_TOL^2 tr(Jn Jn^T), as the kernels test it (one Cholesky)
    return bool(sv[m - 1] ** 2 > RANK_TOL**2 * float(sv @ sv))


def smooth(dq: np.ndarray, hard: Bounds, soft: Bounds) -> tuple[np.ndarray, np.ndarray]:
    """Step 3: the joint velocity moves from where the smoothness limits are centred (the
    previous velocity, carried on at the previous acceleration under a jerk limit) toward
    ``dq`` as far as they allow, along a straight line: ``u + tau (dq - u)`` with the largest
    ``tau`` in [0, 1]. A joint that this leaves outside its hard bounds is put on them (the
    hard limit wins); returns the velocity and those joints."""
    lower, upper = soft.lower, soft.upper
    base = 0.5 * (np.where(np.isfinite(lower), lower, upper) + np.where(np.isfinite(upper),
                                                                          upper, lower))
    base = np.where(np.isfinite(base), base, dq)
    # a joint whose carried-on motion breaks a hard bound (braking before a position limit)
    # starts from the point of both boxes nearest to it
    both_lo, both_hi = np.maximum(lower, hard.lower), np.minimum(upper, hard.upper)
    fits = both_lo <= both_hi
    base = np.where(fits, np.clip(base, both_lo, both_hi), base)
    change = dq - base
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(change > 0, (upper - base) / change,
                        np.where(change < 0, (lower - base) / change, np.inf))
    tau = float(np.clip(np.min(room, initial=1.0), 0.0, 1.0))
    out = base + tau * change
    torn = (out < hard.lower) | (out > hard.upper)
    return np.clip(out, hard.lower, hard.upper), torn


def project(dq: np.ndarray, Jw: np.ndarray, A: np.ndarray, b: np.ndarray, lower: np.ndarray,
            upper: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """``argmin (x - dq)^T H (x - dq)`` with ``H = Jw^T Jw + rho I`` over the ``moving`` joints
    (``rho``: the mean of ``Jw^T Jw``'s diagonal), subject to ``A x <= b`` and
    ``lower <= x <= upper`` (module docstring, step 2); the others keep ``dq``. When no
    velocity within the bounds meets every row (a pair in penetration that no joint can
    separate fast enough), the answer stays within the bounds, the rows as near as the dual's
    ridge lets them (:func:`nonnegative_qp`). Where that point differs from ``dq``, the answer
    is the same least-cost point from :func:`rest_target` instead (``dq``'s self-motion scaled
    with the share of its task motion the rows let through), so that an arm whose push the
    rows stop comes to rest. Compiled (``kernels.project_rows``, a few microseconds; a bound
    enters its dual only once an answer breaks it, which gives the same point: the optimum of
    the convex problem without a constraint that meets it anyway is the optimum with it);
    :func:`project_reference` is the same in numpy, every finite bound in the dual."""
    out = np.empty(dq.size)
    project_rows(np.asarray(dq, dtype=float), np.asarray(Jw, dtype=float),
                 np.asarray(A, dtype=float), np.asarray(b, dtype=float),
                 np.asarray(lower, dtype=float), np.asarray(upper, dtype=float),
                 np.asarray(moving, dtype=float), out)
    return out


def rest_target(dq: np.ndarray, x: np.ndarray, Jw: np.ndarray, moving: np.ndarray
                ) -> np.ndarray | None:
    """Where the projection starts again once it had to correct ``dq`` (rad/s) to ``x``: the
    least-norm velocity of the task motion ``Jw x`` that ``x`` kept, plus ``dq``'s self-motion
    (``dq`` minus the least-norm velocity of its own task motion ``Jw dq``, on the ``moving``
    joints) scaled by the share ``phi = |Jw x| / |Jw dq|`` of the task motion kept; None where
    ``dq`` stays (no task motion asked, or all kept).

    A method's step carries self-motion along with its push on the task (SJT's per-joint
    scaling, a saturated step); where the rows stop that push, at a target inside an obstacle,
    the self-motion went on alone and the arm drifted in its null space at a few cm/s with
    the hand still (six of sixteen random blocked Panda scenes). Scaled with the push it
    stops with it. And the push the rows stop, projected again, came out as self-motion that
    keeps the contacts (``J^T J + rho I`` charges it little), a slide at 6e-4 to 4e-3 rad/s with
    the hand nearly still (Panda seeds 4, 7 and 11 of ``tests/test_collision_rest.py``): the
    start keeps only the task motion the rows let through. A step the rows do not correct keeps
    its self-motion."""
    cols = np.flatnonzero(moving)
    Jc = Jw[:, cols]
    if Jc.shape[0] == 0:
        return None
    t0, t1 = Jc @ dq[cols], Jc @ x[cols]
    asked = float(t0 @ t0)
    phi = np.sqrt(float(t1 @ t1) / asked) if asked > 0 else 1.0
    if not phi < 1.0:
        return None
    S = Jc @ Jc.T
    S += REST_RIDGE * max(float(np.trace(S)) / S.shape[0], 1e-300) * np.eye(S.shape[0])
    task = Jc.T @ np.linalg.solve(S, t0)
    kept = Jc.T @ np.linalg.solve(S, t1)
    out = dq.copy()
    out[cols] = kept + phi * (dq[cols] - task)
    return out


def project_reference(dq: np.ndarray, Jw: np.ndarray, A: np.ndarray, b: np.ndarray,
                      lower: np.ndarray, upper: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """:func:`project` in numpy: :func:`project_once_reference` from ``dq``, and where that
    corrected ``dq``, again from :func:`rest_target`."""
    x = project_once_reference(dq, Jw, A, b, lower, upper, moving)
    if np.array_equal(x, dq):
        return x
    target = rest_target(dq, x, Jw, moving)
    return x if target is None else project_once_reference(target, Jw, A, b, lower, upper,
                                                           moving)


def project_once_reference(dq: np.ndarray, Jw: np.ndarray, A: np.ndarray, b: np.ndarray,
                           lower: np.ndarray, upper: np.ndarray, moving: np.ndarray
                           ) -> np.ndarray:
    """The least-cost point of :func:`project` from ``dq`` in numpy: the whitened problem
    ``z = L^T (x - x0)``, ``H = L L^T``, has the dual ``min 1/2 y^T (C C^T) y + r^T y`` over
    ``y >= 0`` with ``C = G L^-T`` and ``r = h - G x0`` (``G x <= h``: the rows and the
    finite bounds), solved by :func:`nonnegative_qp`; then ``z = -C^T y``."""
    cols = np.flatnonzero(moving)
    x0 = dq[cols]
    H = Jw[:, cols].T @ Jw[:, cols] if Jw.size else np.zeros((cols.size, cols.size))
    rho = max(float(np.trace(H)) / max(cols.size, 1), 1e-12)
    H += rho * np.eye(cols.size)
    finite_lo, finite_hi = np.isfinite(lower[cols]), np.isfinite(upper[cols])
    eye = np.eye(cols.size)
    G = np.vstack([A[:, cols], -eye[finite_lo], eye[finite_hi]])
    h = np.concatenate([b - A[:, ~moving] @ dq[~moving] if (~moving).any() else b,
                        -lower[cols][finite_lo], upper[cols][finite_hi]])
    L = np.linalg.cholesky(H)
    C = np.linalg.solve(L, G.T).T  # G L^-T
    r = h - G @ x0
    y = nonnegative_qp(C @ C.T, r)
    z = -C.T @ y  # z = L^T (x - x0)
    out = dq.copy()
    # the bounds are hard: rows that no velocity within them meets (the dual unbounded but for
    # its ridge) leave the answer on them, not beyond
    out[cols] = np.clip(x0 + np.linalg.solve(L.T, z), lower[cols], upper[cols])
    return out


def nonnegative_qp(Q: np.ndarray, r: np.ndarray, tol: float = 1e-13) -> np.ndarray:
    """``argmin 1/2 y^T Q y + r^T y`` over ``y >= 0`` for a symmetric PSD ``Q``: the active-set
    method of Lawson and Hanson's NNLS, on the normal equations of the passive set.

    ``Q`` gets a ridge of :data:`DUAL_RIDGE` times its largest diagonal entry: on a singular
    ``Q`` (a row twice, more rows than joints) a passive set's system has many solutions, and
    the one it picks may give the entering row a zero weight, so that the method cycles on it
    and stops short of the optimum. With the ridge the dual is strictly convex and the method
    finite; in the primal a row may then be broken by ``ridge * y``, where ``y`` is its weight
    (the dual of rows softened by a quadratic penalty), far below the stage's tolerances."""
    k = r.size
    y = np.zeros(k)
    passive = np.zeros(k, dtype=bool)
    scale = tol * (1.0 + float(np.max(np.abs(r), initial=0.0)))
    # a row no motion can change (Q_tt = 0: its gradient is zero, e.g. two links that move
    # together) cannot be corrected: it never enters, instead of stalling every round
    top = float(np.max(np.diag(Q), initial=0.0))
    inert = np.diag(Q) <= 1e-14 * max(top, 1e-300)
    Q = Q + DUAL_RIDGE * top * np.eye(k)
    for _ in range(3 * k + 10):
        w = -(Q @ y + r)
        w[passive | inert] = -np.inf
        t = int(np.argmax(w)) if k else 0
        if k == 0 or w[t] <= scale:
            break
        passive[t] = True
        for _ in range(3 * k + 10):
            idx = np.flatnonzero(passive)
            s = np.zeros(k)
            s[idx] = np.linalg.lstsq(Q[np.ix_(idx, idx)], -r[idx], rcond=None)[0]
            if np.all(s[idx] > 0):
                y = s
                break
            negative = idx[s[idx] <= 0]
            # the step toward s stops where the first of them reaches 0; one already at 0 with
            # s = 0 too (a degenerate passive set: lstsq on a singular Q) stops it at once,
            # where the ratio 0/0 would have made y NaN
            gap = y[negative] - s[negative]
            alpha = float(np.min(np.where(gap > 0, y[negative] / np.where(gap > 0, gap, 1.0),
                                          0.0)))
            y = y + alpha * (s - y)
            passive &= y > 1e-15
            y[~passive] = 0.0
            if not passive.any():
                break
    return y
