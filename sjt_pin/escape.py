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
against a joint limit) the curvature is not negative, nothing fires, and the arm rests; the
test is not repeated until the configuration or the error changes.
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
    ERROR_FLOOR = 1e-6  #: |e| below this (task units) is converged, not stalled
    WINDOW = 50  #: stalled steps before the curvature test
    MAX_WAIT = 64  #: the longest run (in windows) between tests at a persistent minimum
    PROGRESS = 0.01  #: ... during which |e| fell by less than this fraction
    FD_STEP = 1e-4  #: rad or m: finite-difference step of the Hessian
    CURVATURE = 1e-6  #: a curvature below -CURVATURE |e_w|^2 (per rad^2) is a saddle
    SPEED = 0.5  #: escape speed as a fraction of the URDF speed limits
    DEFAULT_SPEED = 1.0  #: rad/s or m/s for joints without a URDF speed limit
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
        #: escapes started since construction (or the last reset)
        self.escapes = 0

    @property
    def active(self) -> bool:
        """Whether an escape velocity is being added."""
        return self.direction is not None

    def observe(self, run: float, e_sq: float) -> bool:
        """A stall seen by the step kernel (a stall ratio below ``STALL_RATIO`` with ``|e|``
        above ``ERROR_FLOOR``), which counts the stalled steps of a run in ``run`` and asks
        Python only on the first (``run == 1``) and when ``run`` reaches :attr:`wait`. True
        when the curvature should be tested: a window of stalled steps without progress. After
        a test that found no saddle the window doubles (up to ``MAX_WAIT`` windows), so a
        persistent minimum costs a test ever more rarely; a new run starts from ``WINDOW``
        again. The caller restarts the kernel's count after a window."""
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
        if not curvatures[0] < -self.CURVATURE * 2.0 * f0:
            return False
        direction = np.zeros(nv)
        direction[columns] = vectors[:, 0]
        # the sign that lowers f (its third-order term), as seen a little further out
        reach = 1e2 * h
        _, ep = rows(pin.integrate(self.model, q, reach * direction))
        _, em = rows(pin.integrate(self.model, q, -reach * direction))
        if ep @ ep > em @ em:
            direction = -direction
        self.direction = direction
        moving = np.abs(direction) > 1e-12
        self._top = self.SPEED * float(np.min(self.speeds[moving] / np.abs(direction[moving])))
        self.speed = 0.0
        self._travel = 0.0
        self._leaving = False
        self._start_error = None
        self.escapes += 1
        return True

    def velocity(self, regular_speed: float, dt: float, e_sq: float = 0.0
                 ) -> np.ndarray | None:
        """The escape's joint velocity for this step (rad/s, m/s), or ``None`` once it has
        ramped down; ``regular_speed`` is the norm of the regular update's joint velocity and
        ``e_sq`` the squared task error of the step (the escape yields if it grows)."""
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
        accel = self._top / self.RAMP
        if not self._leaving and (regular_speed >= self.speed > 0.0
                                  or self._travel >= self.MAX_TRAVEL):
            self._leaving = True
        if self._leaving:
            self.speed = max(self.speed - accel * dt, 0.0)
            if self.speed == 0.0:
                self.direction = None
                self._wait = self.WINDOW
                return None
        else:
            self.speed = min(self.speed + accel * dt, self._top)
        self._travel += self.speed * dt
        return self.speed * self.direction
