"""The saddle escape's curvature test (:class:`~sjt_pin.escape.SaddleEscape`), a task-row
evaluation at a time.

:meth:`CurvatureTest.run` computes, by central differences over the free joints (2 n
evaluations of the task rows ``rows(q) -> (J_w, e_w)``), the Jacobian H of ``-J_w^T e_w``: the
field a transpose update follows, the exact gradient of ``f = 1/2 |e_w|^2`` for position and
orientation rows and its first-order approximation for pose rows. A clearly negative eigenvalue
of H's symmetric part is a saddle where f, probed further out along its eigenvector, falls
(:meth:`CurvatureTest._descent`), and that eigenvector the escape's direction (the sign that
lowers f, or where both do, the one with more room before a position limit). A zero curvature
is probed further out too (:meth:`CurvatureTest._flat_descent`); at a minimum whose curvatures
span orders of magnitude, the Newton step along the flattest ones is the settling step
(:meth:`CurvatureTest._settle`).

:meth:`~CurvatureTest.run` is a generator that pauses after each evaluation of the rows, after
its setup (the free joints), after the eigen-decomposition (a compiled call:
``kernels.symmetric_eigen``) and before the settling step's model, and returns a
:class:`Finding`: a solver advances it by one pause per step, so that no step evaluates the
rows more than once beyond its own, nor runs more than a few of the test's numpy calls (the
two-frame paths of ``sjt-pin bench speed``: a test of 13–18 evaluations on UR5 was one step of
0.33–0.6 ms, 24–53 times the median step; its code is cold after hundreds of steps, where
numpy's ``eigh`` of 6 x 6 took 33–82 us). It reads nothing that changes before it returns, so
the same arguments run it again to the same pause, bitwise: a copy of a solver taken during a
test replays it.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import kernels

Rows = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Finding:
    """What a curvature test found at ``q``.

    ``kind``: ``"seen"`` (tested here already with the same error: nothing new), ``"minimum"``
    (nothing to do), ``"escape"`` (a saddle: leave along ``direction``) or ``"settle"`` (travel
    ``distance`` along ``direction``, the Newton step along the flattest curvatures).
    ``f``: 1/2 |e_w|^2 at q; ``direction``: a unit joint velocity (nv,) or ``None``;
    ``kept``: at a minimum with directions of zero or negative curvature (along which the
    method's own step would only creep), an orthonormal (nv, r) basis of the others: the
    positive curvatures' directions and each joint the test left out; ``None`` where there are
    no such directions."""

    kind: str
    f: float
    direction: np.ndarray | None = None
    distance: float = 0.0
    kept: np.ndarray | None = None


def _evaluated(rows: Rows, q: np.ndarray) -> Generator[None, None, tuple[np.ndarray, np.ndarray]]:
    """``rows(q)``, then a pause (the unit of work a solver's step takes)."""
    result = rows(q)
    yield
    return result


class CurvatureTest:
    """The curvature test's settings and its arguments that stay fixed (see the module
    docstring).

    Args:
        model: the robot's Pinocchio model (to integrate the test displacements).
        chain: (nv,) 1 for the joints that move the tasks.
        position_limit: the solver's :class:`~sjt_pin.limits.PositionLimit` or ``None``.
    """

    FD_STEP = 1e-4  #: rad or m: finite-difference step of the Hessian
    CURVATURE = 1e-6  #: a curvature below -CURVATURE |e_w|^2 (per rad^2) is a saddle
    FLAT = 1e-6  #: curvatures within this fraction of the largest count as zero
    PROBE = 0.2  #: rad (or m): how far a flat direction (a negative one at most) is probed
    PROBE_NEWTON = 2  #: Newton steps that bring the other joints to the valley floor
    PROBE_DROP = 1e-3  #: a fall of f by this fraction along a flat direction is a saddle
    #: ... along a negative one (whose curvature already says f falls): a fall beyond round-off
    ESCAPE_DROP = 1e-6
    SLOW = 0.1  #: curvatures below this fraction of the largest: what a settling step takes
    SETTLE = 1e-4  #: rad (or m): the shortest Newton step worth travelling at a minimum
    TRUST = 0.25  #: ... when f falls by this fraction of what its quadratic model predicts
    BACKTRACK = 4  #: halvings of the step tried before giving up
    #: a settling step is taken only where f is below its value (for the current targets)
    #: where the last one started, if that is within MAX_TRAVEL, by this fraction: with a
    #: posture beside SJT, Panda stretched toward a target 1.5 m beyond reach took one every
    #: 0.25 s for good, at up to 0.6 rad/s, the regular update bringing f back up each time
    #: (TIAGo's settling steps, which the test suite checks, lower it by 7e-4 to 1.4e-5 of
    #: itself each)
    SETTLED = 1e-9
    MAX_TRAVEL = 0.5  #: rad: the longest settling step, and how near its start the gate holds

    def __init__(self, model: pin.Model, chain: np.ndarray, position_limit=None):
        self.model = model
        self.chain = np.asarray(chain, dtype=bool)
        self.position_limit = position_limit

    def run(self, q: np.ndarray, rows: Rows, tested: tuple[np.ndarray, float] | None = None,
            settled_at: np.ndarray | None = None) -> Generator[None, None, Finding]:
        """Test the curvature of f at ``q``; ``tested``: where the last test ran and f there
        (a test at the same q and f finds ``"seen"``); ``settled_at``: where the last settling
        step started, or ``None``."""
        J_w, e_w = yield from _evaluated(rows, q)
        f0 = 0.5 * float(e_w @ e_w)
        if tested is not None:
            q_seen, f_seen = tested
            if np.array_equal(q_seen, q) and abs(f_seen - f0) <= 1e-3 * f_seen:
                return Finding("seen", f0)  # a minimum stays a minimum
        columns = self._free(q)
        if columns.size == 0:
            return Finding("minimum", f0)
        h, nv = self.FD_STEP, J_w.shape[1]
        H = np.empty((columns.size, columns.size))
        dv = np.zeros(nv)
        yield
        for a, j in enumerate(columns):
            dv[j] = h
            Jp, ep = yield from _evaluated(rows, pin.integrate(self.model, q, dv))
            Jm, em = yield from _evaluated(rows, pin.integrate(self.model, q, -dv))
            dv[j] = 0.0
            H[:, a] = -(ep @ Jp - em @ Jm)[columns] / (2.0 * h)  # d(grad f)/dq_j
        curvatures, vectors = np.empty(columns.size), np.empty((columns.size, columns.size))
        kernels.symmetric_eigen(H, curvatures, vectors)
        yield
        if curvatures[0] < -self.CURVATURE * 2.0 * f0:
            direction = np.zeros(nv)
            direction[columns] = vectors[:, 0]
            # the sign that lowers f (its third-order term), as seen a little further out; when
            # both do (a symmetric saddle), the one with more room before a position limit
            reach = 1e2 * h
            _, ep = yield from _evaluated(rows, pin.integrate(self.model, q, reach * direction))
            _, em = yield from _evaluated(rows, pin.integrate(self.model, q, -reach * direction))
            both = max(ep @ ep, em @ em) < 2.0 * f0
            if (self.room(q, -direction) > self.room(q, direction) if both
                    else ep @ ep > em @ em):
                direction = -direction
            # confirmed further out (``_descent``), no further than where the quadratic model
            # would halve f, the other joints brought down along the curvatures the regular
            # update settles quickly (a Newton step on the slow ones is long and unreliable)
            probe = min(self.PROBE, float(np.sqrt(f0 / -curvatures[0])))
            stiff = curvatures > self.SLOW * float(curvatures[-1])
            found = yield from self._descent(q, rows, columns, curvatures, vectors, f0,
                                             [direction, -direction], probe, stiff,
                                             self.ESCAPE_DROP, first=True)
            if found is None:
                return self._minimum(f0, columns, curvatures, vectors)
            return Finding("escape", f0, found)
        found = yield from self._flat_descent(q, rows, columns, curvatures, vectors, f0)
        if found is not None:
            return Finding("escape", f0, found)
        yield
        settling = yield from self._settle(q, rows, J_w, e_w, columns, curvatures, vectors, f0,
                                           settled_at)
        if settling.kind == "minimum":
            return self._minimum(f0, columns, curvatures, vectors)
        return settling

    def _minimum(self, f0, columns, curvatures, vectors) -> Finding:
        """A minimum at f0, with the basis of its directions other than those of zero or
        negative curvature (:attr:`Finding.kept`) where it has any."""
        nv = self.model.nv
        soft = curvatures <= self.FLAT * float(curvatures[-1])
        if not soft.any():
            return Finding("minimum", f0)
        others = np.setdiff1d(np.arange(nv), columns)
        stiff = int((~soft).sum())
        kept = np.zeros((nv, stiff + others.size))
        kept[columns, :stiff] = vectors[:, ~soft]
        kept[others, stiff + np.arange(others.size)] = 1.0
        return Finding("minimum", f0, kept=kept)

    def toward(self, now: np.ndarray, q: np.ndarray, finding: Finding) -> tuple[np.ndarray, float]:
        """A settling step found at ``q`` taken from ``now`` (where the arm is when the test,
        spread over steps, ends): the unit direction and distance to the configuration it
        found. (The arm may creep meanwhile: TIAGo's arm at 2e-2 rad/s.)"""
        assert finding.direction is not None
        goal = pin.integrate(self.model, q, finding.distance * finding.direction)
        delta = pin.difference(self.model, now, goal)
        distance = float(np.linalg.norm(delta))
        return (delta / distance if distance > 0.0 else delta), distance

    def _free(self, q: np.ndarray) -> np.ndarray:
        """The columns the test differentiates: the chain's joints not at a position limit."""
        free = self.chain.copy()
        pl = self.position_limit
        if pl is not None and pl.active:
            qv = q[pl.q_index]
            near = (qv - pl.lower < 10 * self.FD_STEP) | (pl.upper - qv < 10 * self.FD_STEP)
            free[pl.v_index[near]] = False
        return np.flatnonzero(free)

    def room(self, q: np.ndarray, direction: np.ndarray) -> float:
        """How far (rad or m along the unit ``direction``) q can move before a joint reaches a
        position limit (inf without limits)."""
        pl = self.position_limit
        if pl is None or not pl.active:
            return float("inf")
        x, d = q[pl.q_index], direction[pl.v_index]
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(d > 0.0, (pl.upper - x) / d, np.where(d < 0.0, (pl.lower - x) / d,
                                                                   np.inf))
        return float(np.min(room, initial=np.inf))

    def _settle(self, q, rows, J_w, e_w, columns, curvatures, vectors, f0, settled_at
                ) -> Generator[None, None, Finding]:
        """At a minimum (no saddle): the Newton step along its flat directions, if it helps.

        A redundant arm at a target it cannot reach stops at a minimum of f whose Hessian is
        badly conditioned (Baxter's arm: curvatures 6e-4 to 2.9 on the unit-norm columns): the
        regular update, a gradient step damped for the largest curvature, creeps along the
        flattest directions for seconds. The Newton step ``-H^+ grad f`` restricted to the
        curvatures below ``SLOW`` of the largest (the others the regular update settles within
        a few steps; those within ``FLAT`` of zero, the self-motion, left out), at most
        ``MAX_TRAVEL`` long (halved up to ``BACKTRACK`` times until f, evaluated there, falls by
        ``TRUST`` of the model's fall at least), is the settling step when it is still longer
        than ``SETTLE``. It gives up no error: it goes where f is lower.
        """
        minimum = Finding("minimum", f0)
        top = float(curvatures[-1])
        slow = (curvatures > self.FLAT * top) & (curvatures < self.SLOW * top)
        if top <= 0.0 or not slow.any():
            return minimum
        if (settled_at is not None
                and np.linalg.norm(pin.difference(self.model, settled_at, q)) <= self.MAX_TRAVEL):
            _, e_at = yield from _evaluated(rows, settled_at)
            if f0 > (1.0 - self.SETTLED) * 0.5 * float(e_at @ e_at):
                return minimum  # not below where the last one started: the arm is held there
        yield
        gradient = -(e_w @ J_w)[columns]
        projected = vectors[:, slow].T @ gradient
        step = -vectors[:, slow] @ (projected / curvatures[slow])
        full = float(np.linalg.norm(step))
        if full < self.SETTLE:
            return minimum
        direction = np.zeros(J_w.shape[1])
        direction[columns] = step / full
        model_fall = float(projected @ (projected / curvatures[slow]))
        shrink = min(1.0, self.MAX_TRAVEL / full)
        for _ in range(self.BACKTRACK):  # halve the step until f falls as the model says
            distance = shrink * full
            # the quadratic model's fall along the shortened step, and f's own
            predicted = shrink * (1.0 - 0.5 * shrink) * model_fall
            _, e_far = yield from _evaluated(
                rows, pin.integrate(self.model, q, distance * direction))
            if f0 - 0.5 * float(e_far @ e_far) > self.TRUST * predicted > 0.0:
                break
            shrink *= 0.5
        else:
            return minimum
        if distance < self.SETTLE:
            return minimum
        return Finding("settle", f0, direction, distance)

    def _flat_descent(self, q, rows, columns, curvatures, vectors, f0
                      ) -> Generator[None, None, np.ndarray | None]:
        """A direction of zero curvature along which ``f`` falls at higher order, or ``None``.

        Where H has a zero eigenvalue (a null direction of J whose coupling to the others
        vanishes), the second-order test cannot tell a minimum from a saddle: UR5 at q = 0 asked
        to roll about its lost axis is one with a pose task's length L below 0.75 m, where f
        falls like -t^4 along the null direction once the other joints follow. Each flat
        direction v is probed at ``q (+) +-PROBE v``, the other free joints brought to the
        valley floor by ``PROBE_NEWTON`` Newton steps on H's other eigenvectors; a fall of f
        by more than ``PROBE_DROP`` of its value makes v the escape direction (the sign that
        falls most). Along the self-motion of a redundant arm f stays flat and nothing fires.
        """
        top = float(curvatures[-1])
        flat = np.abs(curvatures) <= self.FLAT * top
        if top <= 0.0 or not flat.any() or flat.all():
            return None
        nv = self.model.nv
        candidates = []
        for k in np.flatnonzero(flat):
            for sign in (1.0, -1.0):
                v = np.zeros(nv)
                v[columns] = sign * vectors[:, k]
                candidates.append(v)
        return (yield from self._descent(q, rows, columns, curvatures, vectors, f0, candidates,
                                         self.PROBE, ~flat, self.PROBE_DROP))

    def _descent(self, q, rows, columns, curvatures, vectors, f0, candidates, probe, keep,
                 drop, first=False) -> Generator[None, None, np.ndarray | None]:
        """The one of the unit ``candidates`` along which f falls most (with ``first``, the
        first in their order), probed ``probe`` out with the other free joints brought to the
        valley floor by ``PROBE_NEWTON`` Newton steps on H's curvatures ``keep`` (a mask), if by
        more than ``drop`` of the lower of f at q and that floor below q; or ``None``.

        A curvature test sees f to second order over ``FD_STEP``; an escape travels
        ``MAX_TRAVEL``. Along the self-motion of a redundant arm whose target is out of reach,
        f's curvature can be negative by a few millionths of the largest and turn positive a
        few hundredths of a radian out: xArm7 (JT, a target 0.26 m beyond reach, acceleration
        and jerk limits) left such a "saddle" at 1.6 rad/s, travelled 0.5 rad with f rising,
        settled back and left again, once a second for good. So a direction of negative or
        zero curvature is an escape only where f falls by this probe.
        """
        inverse = (vectors[:, keep] / curvatures[keep]) @ vectors[:, keep].T
        nv = self.model.nv

        def valley(v: np.ndarray) -> Generator[None, None, float]:
            """f at q (+) probe v with the other joints at the valley floor"""
            qt = pin.integrate(self.model, q, probe * v)
            for _ in range(self.PROBE_NEWTON):
                J_w, e_w = yield from _evaluated(rows, qt)
                step = np.zeros(nv)
                step[columns] = inverse @ (e_w @ J_w)[columns]
                qt = pin.integrate(self.model, qt, step)
            _, e_w = yield from _evaluated(rows, qt)
            return 0.5 * float(e_w @ e_w)

        # the floor below q itself: what the regular update reaches without the direction
        floor = yield from valley(np.zeros(nv))
        best, found = (1.0 - drop) * min(f0, floor), None
        for v in candidates:
            f = yield from valley(v)
            if f < best:
                if first:
                    return v
                best, found = f, v
        return found
