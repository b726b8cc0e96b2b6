"""Smooth escape from the saddles of exactly singular configurations (every built-in method).

At an exactly singular configuration an error along the lost task direction gives
``J^T e = 0`` although ``e != 0``: the updates stop (the transpose's, and the pseudoinverse's
and damped solve's, which drop or damp that direction), though ``1/2 |e|^2`` is not
at a minimum but at a saddle (UR5 at q = 0, asked to roll its tool about the lost axis, never
moves). Round-off alone takes thousands of steps to leave it.

:class:`SaddleEscape` watches each step's stall ratio (the loop gain along the command, see
:func:`~sjt_pin.kernels.transpose_step`). After ``WINDOW`` steps without progress it tests the
curvature of ``f = 1/2 |e_w|^2`` over the free joints (:class:`~sjt_pin.curvature.CurvatureTest`),
spread over the next steps, one evaluation of the task rows a step (a test whose stall ends
first is dropped). Only a clearly negative curvature along which f, probed further out, falls
starts an escape: a joint velocity along the most negative direction, ramped up and later down
within ``RAMP`` seconds, at ``SPEED`` times the URDF speed limits at most (also when the
solver's speed limits are off), added to the regular update until that update moves faster
than the escape's top speed. At a true minimum (an unreachable target, a target held against a
joint limit, or one reachable only on another branch of the inverse kinematics: UR10 with its elbow
exactly straight and the error along the direction the stretched arm cannot move in, pointing
outward — bending the elbow raises the error) the curvature is not negative, nothing fires,
and the arm rests (``StepInfo.stalled``): the method's own feedback, which would creep on along
the minimum's flat directions (zero or negative curvature), leaves them out until the stall
ends (the controller's ``resting``). The test is not repeated until the configuration or the
error changes. At a minimum whose curvatures span orders of magnitude (a redundant arm at a
target out of reach), the escape travels the test's Newton step along the flattest curvatures
instead, so that the arm comes to rest at the bottom rather than creeping towards it for
seconds. All thresholds are relative or in joint units, so the same run in mm and in m takes
the same decisions.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Generator

import numpy as np
import pinocchio as pin

from .curvature import CurvatureTest, Finding, Rows


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
    SPEED = 0.5  #: escape speed as a fraction of the URDF speed limits
    DEFAULT_SPEED = 1.0  #: rad/s or m/s for joints without a URDF speed limit
    RAMP = 0.1  #: s to ramp the escape velocity up, and down
    #: rad: an escape ends after moving this far along its direction (the settling steps'
    #: longest, too)
    MAX_TRAVEL = CurvatureTest.MAX_TRAVEL
    #: an escape ramps down once |e| exceeds its value at the start by this fraction, and
    #: stops at once past twice that: it never raises the error by more than about 10 %
    GROWTH = 0.05

    def __init__(self, model: pin.Model, chain: np.ndarray, speed_limits: np.ndarray,
                 position_limit=None):
        #: the curvature test's settings (:class:`~sjt_pin.curvature.CurvatureTest`)
        self.curvature = CurvatureTest(model, chain, position_limit)
        limits = np.asarray(speed_limits, dtype=float)
        self.speeds = np.where(np.isfinite(limits), limits, self.DEFAULT_SPEED)
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
        #: a test under way: (q, targets, pauses taken), and its generator (not copied)
        self._pending: tuple[np.ndarray, list, int] | None = None
        self._run: Generator[None, None, Finding] | None = None
        #: a test found a minimum with flat directions: the (nv, r) basis of the others, the
        #: only ones the controller's first level moves along while the stall lasts
        self._kept: np.ndarray | None = None
        #: escapes started since construction (or the last reset)
        self.escapes = 0
        #: Newton steps travelled at minima (see :meth:`CurvatureTest._settle
        #: <sjt_pin.curvature.CurvatureTest._settle>`)
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

    @property
    def testing(self) -> bool:
        """Whether a curvature test is under way (one evaluation of the task rows a step)."""
        return self._pending is not None

    @property
    def busy(self) -> bool:
        """Whether the solver must call :meth:`follow` on its next step (an escape is added or
        a test is under way)."""
        return self.direction is not None or self._pending is not None

    def test(self, q: np.ndarray, rows: Rows) -> bool:
        """Test the curvature of ``f = 1/2 |e_w|^2`` at ``q`` at once (not spread over steps),
        ``rows(q) -> (J_w, e_w)`` giving the weighted task rows; start an escape (or a settling
        step) if it finds one. True when it does. (A solver spreads its tests over its steps;
        it tests at once only where its targets cannot be copied.)"""
        run = self.curvature.run(q, rows, self._tested, self._settled_at)
        while True:
            try:
                next(run)
            except StopIteration as done:
                return self._apply(q, done.value, q)

    def _apply(self, q: np.ndarray, finding: Finding, now: np.ndarray) -> bool:
        """Act on a test that ran at ``q`` and finished with the arm at ``now``: start what it
        found (a settling step toward the configuration it found, from ``now``); remember where
        it ran."""
        if finding.kind == "seen":
            return False
        self._tested = (q.copy(), finding.f)
        if finding.direction is None:  # a minimum: rest along its flat directions
            self._kept = finding.kept
            return False
        if finding.kind == "settle":
            direction, distance = finding.direction, finding.distance
            if now is not q and not np.array_equal(now, q):
                direction, distance = self.curvature.toward(now, q, finding)
            if distance < self.curvature.SETTLE:
                return False
            self._start(direction, 0.5 * distance, distance / self.RAMP)
            self._settling, self._tick = True, 0
            self._settled_at = now.copy()
            self.settles += 1
        else:
            self._start(finding.direction, self.MAX_TRAVEL)
            self.escapes += 1
        return True

    def _begin(self, q: np.ndarray, targets: list, rows_for: Callable[[list], Rows]) -> None:
        """Start a test at ``q`` for ``targets``, spread over the next steps (its first
        evaluation on the next: this step copied the targets); where the targets cannot be
        copied (a task of one's own), at once."""
        try:
            kept = copy.deepcopy(targets)
        except Exception:  # noqa: BLE001 - any failure to copy: test here, at once
            self.test(q, rows_for(targets))
            return
        self._pending, self._run = (q.copy(), kept, 0), None

    def _advance(self, rows_for: Callable[[list], Rows], now: np.ndarray) -> None:
        """One pause of the test under way, the arm at ``now`` (a copy first replays the pauses
        its original had taken); where the test ends, what it found (if anything) is started
        and :attr:`testing` turns false. An error raised meanwhile (by a task's rows) ends the
        test and is raised."""
        assert self._pending is not None
        q, targets, done = self._pending
        try:
            if self._run is None:
                self._run = self.curvature.run(q, rows_for(targets), self._tested,
                                               self._settled_at)
                for _ in range(done):
                    next(self._run)
            next(self._run)
        except StopIteration as finished:
            self._pending = self._run = None
            if finished.value is not None:  # (None: a replay that ended early; nothing found)
                self._apply(q, finished.value, now)
            return
        except BaseException:
            self._pending = self._run = None
            raise
        self._pending = (q, targets, done + 1)

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_run"] = None  # (a generator: a copy replays it from _pending)
        return state

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
        # (against the top speed, not the ramp's: a regular update that already creeps
        # along a flat direction ended every escape on its first step, and the arm crept on)
        if not self._leaving and (regular_speed >= self._top > 0.0
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

    def follow(self, controller, stalled: bool, q: np.ndarray, dt: float, targets: list,
               rows_for: Callable[[list], Rows]) -> None:
        """One step of a solver's compiled ``controller`` (``sjt_pin.kernels.Controller``)
        seen by the escape: a stall run (``stalled``) observed, a curvature test begun at ``q``
        for ``targets`` or advanced by one evaluation of the rows ``rows_for(targets)``
        (dropped if the stall ends first); then the escape's velocity for the next step written
        into the controller, or its end cleared. The solver calls it on every step while
        :attr:`busy`."""
        c = controller
        if self._pending is not None:
            # a test no longer describes the arm once its stall ends. (Targets that move while
            # the arm stays stalled keep the test's: on two frames' circles the error grows by
            # 1 % a step during a test, and dropping a test once it had moved by 10 % dropped
            # every one; what the test finds yields by itself if the error grows.)
            if c.stall_run < 0.0:
                self._pending = self._run = None
                c.stall_wait = self.wait
            else:
                try:
                    self._advance(rows_for, q)
                finally:  # ended, or a task's rows raised: the kernel counts a new window
                    if self._pending is None:
                        c.stall_run, c.stall_wait = 0.0, self.wait
        elif stalled and not self.active:
            run = c.stall_run
            if run > 1.0:  # a window ended: the kernel counts the next one
                c.stall_run = 0.0
            try:
                if self.observe(run, c.ew_sq):
                    self._begin(q, targets, rows_for)
            finally:  # (no window ends while a test is under way)
                c.stall_wait = self.wait if self._pending is None else float("inf")
        if self._kept is not None:  # (the controller clears it when the stall ends)
            rank = self._kept.shape[1]
            c.rest_keep[:self._kept.size] = self._kept.ravel()
            c.rest_rank, c.resting, self._kept = rank, True, None
        velocity = None if not self.active else self.velocity(c.regular, dt, c.ew_sq)
        if velocity is None:
            if c.escaping:  # an escape ended: a stall after it is a new run
                c.stall_run = -1.0
                c.escaping = False
                c.escape_velocity[:] = 0.0
        else:  # the kernel adds it, within the limits, from the next step on
            c.escaping = True
            c.escape_velocity[:] = velocity
