"""Smooth escape from the saddles of exactly singular configurations (JT and SJT).

At an exactly singular configuration an error along the lost task direction gives
``J^T e = 0`` although ``e != 0``: the transpose-type updates stop, though ``1/2 |e|^2`` is not
at a minimum but at a saddle (UR5 at q = 0, asked to roll its tool about the lost axis, never
moves). Round-off alone takes thousands of steps to leave it.

:class:`SaddleEscape` watches each step's stall ratio (the loop gain along the command, see
:func:`~sjt_pin.kernels.transpose_step`). After ``WINDOW`` steps without progress it
computes, by central differences over the free joints (those of the tasks' chains that are
not at a position limit; 2 n evaluations of the task rows), the Jacobian H of ``-J_w^T e_w``:
the field a transpose update follows, the exact gradient of ``f = 1/2 |e_w|^2`` for position
and orientation rows and its first-order approximation for pose rows. A negative eigenvalue
of H's symmetric part makes the equilibrium of the update unstable: a saddle. That negative
curvature is often a mix of a null direction of J and a direction J keeps, so the whole H is
needed, not its restriction to the small singular directions. Only a clearly
negative curvature starts an escape: a joint velocity along the most negative direction,
ramped up and later down within ``RAMP`` seconds, at ``SPEED`` times the URDF speed limits at
most (also when the solver's speed limits are off), added to the regular update until that
update moves faster than the escape. At a true minimum (an unreachable target, a target held
against a joint limit, or one reachable only on another branch of the inverse kinematics: UR10
with its elbow exactly straight and the error along the direction the stretched arm cannot
move in, pointing outward — bending the elbow raises the error) the curvature is not negative,
nothing fires, and the arm rests (``StepInfo.stalled``); the test is not repeated until the
configuration or the error changes.

Two refinements of the test: a zero curvature is probed further out (a saddle of fourth order,
:meth:`SaddleEscape._flat_descent`), and of the two signs of a symmetric escape the one with
more room before a position limit is taken. At a minimum whose curvatures span orders of
magnitude (a redundant arm at a target out of reach), the escape travels Newton steps along
the flattest curvatures instead (:meth:`SaddleEscape._settle`), so that the arm comes to rest
at the bottom rather than creeping towards it for seconds. All thresholds are relative or in
joint units, so the same run in mm and in m takes the same decisions.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin


class SaddleEscape:
    """The escape state of one solver (see the module docstring).

    Args:
        model: the robot's Pinocchio model (to integrate the test displacements).
        chain: (nv,) 1 for the joints that move the tasks.
        speed_limits: (nv,) URDF speed limits (rad/s, m/s; ``inf`` where none).
        position_limit: the solver's :class:`~sjt_pin.limits.PositionLimit` or ``None``.
    """

    STALL_RATIO = 1e-4  #: loop gain along the command below this (of tr) counts as stalled
    #: |e_w| below this times the tasks' length (see :func:`~sjt_pin.tasks.pose.tasks_length`) is
    #: converged, not stalled: 1e-6 m on a 1 m arm, 1e-3 mm on the same arm in mm
    ERROR_FLOOR = 1e-6
    WINDOW = 50  #: stalled steps before the curvature test
    MAX_WAIT = 64  #: the longest run (in windows) between tests at a persistent minimum
    PROGRESS = 0.01  #: ... during which |e| fell by less than this fraction
    FD_STEP = 1e-4  #: rad or m: finite-difference step of the Hessian
    CURVATURE = 1e-6  #: a curvature below -CURVATURE |e_w|^2 (per rad^2) is a saddle
    SPEED = 0.5  #: escape speed as a fraction of the URDF speed limits
    DEFAULT_SPEED = 1.0  #: rad/s or m/s for joints without a URDF speed limit
    FLAT = 1e-6  #: curvatures within this fraction of the largest count as zero
    PROBE = 0.2  #: rad (or m): how far a flat direction is probed
    PROBE_NEWTON = 2  #: Newton steps that bring the other joints to the valley floor
    PROBE_DROP = 1e-3  #: a fall of f by this fraction along a flat direction is a saddle
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
    RAMP = 0.1  #: s to ramp the escape velocity up, and down
    MAX_TRAVEL = 0.5  #: rad: an escape ends after moving this far along its direction
    #: an escape ramps down once |e| exceeds its value at the start by this fraction, and
    #: stops at once past twice that: it never raises the error by more than about 10 %
    GROWTH = 0.05

    def __init__(self, model: pin.Model, chain: np.ndarray, speed_limits: np.ndarray,
                 position_limit=None):
        self.model = model
        self.chain = np.asarray(chain, dtype=bool)
        limits = np.asarray(speed_limits, dtype=float)
        self.speeds = np.where(np.isfinite(limits), limits, self.DEFAULT_SPEED)
        self.position_limit = position_limit
        self.reset()

    def reset(self) -> None:
        """Forget the stall, any escape in progress and the last curvature test."""
        self._wait = self.WINDOW
        self._error_start = 0.0
        self._tested: tuple[np.ndarray, float] | None = None
        self.direction: np.ndarray | None = None
        self.speed = 0.0
        self._top = 0.0
        self._travel = 0.0
        self._leaving = False
        self._start_error: float | None = None
        self._max_travel = self.MAX_TRAVEL
        self._settling, self._tick = False, 0
        self._settled_at: np.ndarray | None = None  # where the last settling step started
        #: escapes started since construction (or the last reset)
        self.escapes = 0
        #: Newton steps travelled at minima (see :meth:`_settle`)
        self.settles = 0

    @property
    def active(self) -> bool:
        """Whether an escape velocity is being added."""
        return self.direction is not None

    def observe(self, run: float, e_sq: float) -> bool:
        """A stall seen by the step kernel (a stall ratio below ``STALL_RATIO`` with ``|e_w|``
        above ``ERROR_FLOOR`` L; ``e_sq`` the squared weighted error), which counts the stalled
        steps of a run in ``run`` and asks Python only on the first (``run == 1``) and when
        ``run`` reaches :attr:`wait`. True when the curvature should be tested: a window of
        stalled steps without progress. After a test that found no saddle the window doubles
        (up to ``MAX_WAIT`` windows), so a persistent minimum costs a test ever more rarely; a
        new run starts from ``WINDOW`` again. The caller restarts the kernel's count after a
        window."""
        if run <= 1.0:  # a new run of stalled steps
            self._wait, self._error_start = self.WINDOW, e_sq
            return False
        test = e_sq > (1.0 - self.PROGRESS) ** 2 * self._error_start
        self._error_start = e_sq
        if test:
            self._wait = min(2 * self._wait, self.MAX_WAIT * self.WINDOW)
        return test

    @property
    def wait(self) -> int:
        """Stalled steps in the current window before :meth:`observe` decides (the kernel's
        ``P_STALL_WAIT``)."""
        return self._wait

    def test(self, q: np.ndarray, rows: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
             ) -> bool:
        """Test the curvature of ``f = 1/2 |e_w|^2`` at ``q``, ``rows(q) -> (J_w, e_w)`` giving
        the weighted task rows; start an escape if it is clearly negative."""
        J_w, e_w = rows(q)
        f0 = 0.5 * float(e_w @ e_w)
        if self._tested is not None:
            q_seen, f_seen = self._tested
            if np.array_equal(q_seen, q) and abs(f_seen - f0) <= 1e-3 * f_seen:
                return False  # already tested here: a minimum stays a minimum
        self._tested = (q.copy(), f0)
        free = self.chain.copy()
        if self.position_limit is not None and self.position_limit.active:
            pl = self.position_limit
            qv = q[pl.q_index]
            near = (qv - pl.lower < 10 * self.FD_STEP) | (pl.upper - qv < 10 * self.FD_STEP)
            free[pl.v_index[near]] = False
        columns = np.flatnonzero(free)
        if columns.size == 0:
            return False
        h, nv = self.FD_STEP, J_w.shape[1]
        H = np.empty((columns.size, columns.size))
        for a, j in enumerate(columns):
            dv = np.zeros(nv)
            dv[j] = h
            Jp, ep = rows(pin.integrate(self.model, q, dv))
            Jm, em = rows(pin.integrate(self.model, q, -dv))
            H[:, a] = -(ep @ Jp - em @ Jm)[columns] / (2.0 * h)  # d(grad f)/dq_j
        curvatures, vectors = np.linalg.eigh(0.5 * (H + H.T))
        if curvatures[0] < -self.CURVATURE * 2.0 * f0:
            direction = np.zeros(nv)
            direction[columns] = vectors[:, 0]
            # the sign that lowers f (its third-order term), as seen a little further out; when
            # both do (a symmetric saddle), the one with more room before a position limit
            reach = 1e2 * h
            _, ep = rows(pin.integrate(self.model, q, reach * direction))
            _, em = rows(pin.integrate(self.model, q, -reach * direction))
            both = max(ep @ ep, em @ em) < 2.0 * f0
            if (self._room(q, -direction) > self._room(q, direction) if both
                    else ep @ ep > em @ em):
                direction = -direction
        else:
            found = self._flat_descent(q, rows, columns, curvatures, vectors, f0)
            if found is None:
                return self._settle(q, rows, J_w, e_w, columns, curvatures, vectors, f0)
            direction = found
        self._start(direction, self.MAX_TRAVEL)
        self.escapes += 1
        return True

    def _room(self, q: np.ndarray, direction: np.ndarray) -> float:
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

    def _start(self, direction: np.ndarray, travel: float, speed: float = np.inf) -> None:
        """Start a ramped motion along the unit ``direction``: at most ``SPEED`` times the URDF
        speeds and ``speed``, ramping down after ``travel``."""
        self.direction = direction
        moving = np.abs(direction) > 1e-12
        cap = self.SPEED * float(np.min(self.speeds[moving] / np.abs(direction[moving])))
        self._top = min(cap, speed)
        self._max_travel = travel
        self._settling = False
        self.speed = 0.0
        self._travel = 0.0
        self._leaving = False
        self._start_error = None

    def _settle(self, q, rows, J_w, e_w, columns, curvatures, vectors, f0) -> bool:
        """At a minimum (no saddle): the Newton step along its flat directions, if it helps.

        A redundant arm at a target it cannot reach stops at a minimum of f whose Hessian is
        badly conditioned (Baxter's arm: curvatures 6e-4 to 2.9 on the unit-norm columns): the
        regular update, a gradient step damped for the largest curvature, creeps along the
        flattest directions for seconds. The Newton step ``-H^+ grad f`` restricted to the
        curvatures below ``SLOW`` of the largest (the others the regular update settles within
        a few steps; those within ``FLAT`` of zero, the self-motion, left out), at most
        ``MAX_TRAVEL`` long (halved up to ``BACKTRACK`` times until f, evaluated there, falls by
        ``TRUST`` of the model's fall at least), is travelled with the escape's ramps when it is
        still longer than ``SETTLE``.
        It gives up no error: it goes where f is lower, and yields like an escape if f grows.
        """
        top = float(curvatures[-1])
        slow = (curvatures > self.FLAT * top) & (curvatures < self.SLOW * top)
        if top <= 0.0 or not slow.any():
            return False
        at = self._settled_at  # (f there for the current targets, where the arm came back)
        if at is not None and np.linalg.norm(pin.difference(self.model, at, q)) <= self.MAX_TRAVEL:
            _, e_at = rows(at)
            if f0 > (1.0 - self.SETTLED) * 0.5 * float(e_at @ e_at):
                return False  # not below where the last one started: the arm is held there
        gradient = -(e_w @ J_w)[columns]
        projected = vectors[:, slow].T @ gradient
        step = -vectors[:, slow] @ (projected / curvatures[slow])
        full = float(np.linalg.norm(step))
        if full < self.SETTLE:
            return False
        direction = np.zeros(J_w.shape[1])
        direction[columns] = step / full
        model_fall = float(projected @ (projected / curvatures[slow]))
        shrink = min(1.0, self.MAX_TRAVEL / full)
        for _ in range(self.BACKTRACK):  # halve the step until f falls as the model says
            distance = shrink * full
            # the quadratic model's fall along the shortened step, and f's own
            predicted = shrink * (1.0 - 0.5 * shrink) * model_fall
            _, e_far = rows(pin.integrate(self.model, q, distance * direction))
            if f0 - 0.5 * float(e_far @ e_far) > self.TRUST * predicted > 0.0:
                break
            shrink *= 0.5
        else:
            return False
        if distance < self.SETTLE:
            return False
        self._start(direction, 0.5 * distance, distance / self.RAMP)
        self._settling, self._tick = True, 0
        self._settled_at = q.copy()
        self.settles += 1
        return True

    def _flat_descent(self, q, rows, columns, curvatures, vectors, f0) -> np.ndarray | None:
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
        keep = ~flat
        inverse = (vectors[:, keep] / curvatures[keep]) @ vectors[:, keep].T
        nv = self.model.nv

        def valley(v: np.ndarray) -> float:
            """f at q (+) PROBE v with the other joints at the valley floor"""
            qt = pin.integrate(self.model, q, self.PROBE * v)
            for _ in range(self.PROBE_NEWTON):
                J_w, e_w = rows(qt)
                step = np.zeros(nv)
                step[columns] = inverse @ (e_w @ J_w)[columns]
                qt = pin.integrate(self.model, qt, step)
            _, e_w = rows(qt)
            return 0.5 * float(e_w @ e_w)

        # the floor below q itself: what the regular update reaches without the flat direction
        best, found = (1.0 - self.PROBE_DROP) * min(f0, valley(np.zeros(nv))), None
        for k in np.flatnonzero(flat):
            for sign in (1.0, -1.0):
                v = np.zeros(nv)
                v[columns] = sign * vectors[:, k]
                f = valley(v)
                if f < best:
                    best, found = f, v
        return found

    def _settling_velocity(self, dt: float) -> np.ndarray | None:
        """A settling step's velocity: a triangle of 2 RAMP / dt steps that travels the step's
        length exactly, counted in steps (no threshold on a travelled distance that a round-off
        could move by a step: the same run in mm and in m settles alike)."""
        assert self.direction is not None
        n = max(1, int(round(self.RAMP / dt)))
        k = self._tick
        self._tick += 1
        if k >= 2 * n - 1:
            self.direction, self.speed = None, 0.0
            self._wait = self.WINDOW
            return None
        self.speed = self._top * (k + 1 if k < n else 2 * n - 1 - k) / n
        return self.speed * self.direction

    def velocity(self, regular_speed: float, dt: float, e_sq: float = 0.0
                 ) -> np.ndarray | None:
        """The escape's joint velocity for this step (rad/s, m/s), or ``None`` once it has
        ramped down; ``regular_speed`` is the norm of the regular update's joint velocity and
        ``e_sq`` the squared weighted task error |e_w|^2 of the step (the escape yields if it
        grows)."""
        if self.direction is None:
            return None
        if self._start_error is None:
            self._start_error = e_sq
        elif e_sq > (1.0 + 2.0 * self.GROWTH) ** 2 * self._start_error:
            self.direction, self.speed = None, 0.0  # making things worse: stop now
            self._wait = self.WINDOW
            return None
        elif e_sq > (1.0 + self.GROWTH) ** 2 * self._start_error:
            self._leaving = True
        if self._settling and not self._leaving:
            return self._settling_velocity(dt)
        accel = self._top / self.RAMP
        if not self._leaving and (regular_speed >= self.speed > 0.0
                                  or self._travel >= self._max_travel):
            self._leaving = True
        if self._leaving:
            self.speed = max(self.speed - accel * dt, 0.0)
            if self.speed <= 1e-9 * self._top:  # at rest (not a round-off above it)
                self.direction = None
                self._wait = self.WINDOW
                return None
        else:
            self.speed = min(self.speed + accel * dt, self._top)
        self._travel += self.speed * dt
        return self.speed * self.direction

    def follow(self, controller, stalled: bool, q: np.ndarray, dt: float,
               rows: Callable[[], Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]]
               ) -> None:
        """One step of a solver's compiled ``controller`` (``sjt_pin.kernels.Controller``)
        seen by the escape: a stall run (``stalled``) observed, and tested on the task rows
        ``rows()`` (see :meth:`test`); then the escape's velocity for the next step written into
        the controller, or its end cleared."""
        c = controller
        if stalled and not self.active:
            run = c.stall_run
            if self.observe(run, c.ew_sq):
                self.test(q, rows())
            if run > 1.0:  # a window ended: the kernel counts the next one
                c.stall_run = 0.0
            c.stall_wait = self.wait
        velocity = None if not self.active else self.velocity(c.regular, dt, c.ew_sq)
        if velocity is None:
            if c.escaping:  # an escape ended: a stall after it is a new run
                c.stall_run = -1.0
                c.escaping = False
                c.escape_velocity[:] = 0.0
        else:  # the kernel adds it, within the limits, from the next step on
            c.escaping = True
            c.escape_velocity[:] = velocity
