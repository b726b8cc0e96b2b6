"""The ``work`` vector of a solver: parameters, constants, results and scratch, in one array.

A method kernel takes ``(J, e, ff, q, work, step)``: everything that stays fixed between steps
(the parameters, the row weights and gains, the joint mask, the limit box) lives in ``work``,
so a step pays for six arguments, not fifteen. :class:`Layout` says where each part starts;
the kernels read those offsets from the ``P_*`` parameter slots. The slots' numbers come from
the compiled module, which names each slot once: no Python module holds a slot's number.
"""

from __future__ import annotations

import numpy as np

# -- slots: their numbers are the compiled module's (src/kernels.h names each slot once) ---------
from ._kernels import (  # noqa: F401 (re-exported: the kernels' vocabulary)
    BOUND_PRODUCTS,
    BOUND_TOL,
    BRAKING_STEPS,
    BRAKING_TOL,
    CLAMPED,
    DUAL_RIDGE,
    EIGEN_FLOOR,
    FB_DAMPED,
    FB_TRANSPOSE,
    FF_DAMPED,
    FF_TRANSPOSE,
    GAIN_AUTO,
    GAIN_FIXED,
    I_E_SQ,
    I_EW_SQ,
    I_FF_SQ,
    I_GAIN,
    I_LOOP,
    I_REGULAR,
    I_SCALE,
    I_STALL,
    I_TRACE,
    INFO,  # where the results start: after the parameters
    INFO_SIZE,
    L_ACCELERATION,
    L_JERK,
    L_POSITION,
    L_VELOCITY,
    NON_FINITE,
    P_BOX,
    P_BOX_COUNT,
    P_CLAMPED,
    P_COL_TOL,
    P_DT,
    P_ERROR_ROWS,
    P_ESCAPING,
    P_EXTRA,
    P_FB_MODE,
    P_FF_MODE,
    P_GAIN_ARG,
    P_GAIN_MODE,
    P_HAS_FF,
    P_IDENTITY_ROWS,
    P_JERK,
    P_LENGTH2,
    P_LM,
    P_MASK,
    P_MU,
    P_RCOND,
    P_ROWS,
    P_SCALED,
    P_SCRATCH,
    P_SMOOTH,
    P_SPEED,
    P_STALL_ERROR,
    P_STALL_RATIO,
    P_STALL_RUN,
    P_STALL_WAIT,
    RANK_TOL,
    SCALED,
    SM_ACC,
    SM_BRAKE_ACC,
    SM_BRAKE_JERK,
    SM_DDQ,
    SM_DESIRED,
    SM_DQ,
    SM_FF,
    SM_GAINS,
    SM_HARD_HI,
    SM_HARD_HI_BY,
    SM_HARD_LO,
    SM_HARD_LO_BY,
    SM_JERK,
    SM_JERK_SPEED,
    SM_OUT,
    SM_SOFT_HI,
    SM_SOFT_HI_BY,
    SM_SOFT_LO,
    SM_SOFT_LO_BY,
    SM_TORN,
    SMOOTH_SIZE,
    STALLED,
)

HEADER = INFO + INFO_SIZE

# The modes, status bits and tolerances are the compiled module's too (imported above):
#: gain modes (GAIN_FIXED: K as given; GAIN_AUTO: c K / (dt lambda_hat), lambda_hat >=
#: lambda_max(J M)); how a method maps the desired velocity (``P_FF_MODE``; ``P_HAS_FF`` says
#: whether a step has one: FF_TRANSPOSE through the feedback's own mapping, paper eq. 10, 21,
#: FF_DAMPED the damped sqrt(D) solve); the transpose methods' feedback (FB_TRANSPOSE:
#: S J^T K e, eq. 10, 21; FB_DAMPED: through the damped solve); the status bits a step kernel
#: returns (0: nothing to do but integrate; NON_FINITE and STALLED need Python, CLAMPED and
#: SCALED do not); the matrix products of the loop-eigenvalue bound; the smallest eigenvalue of
#: J J^T, relative to the largest, that the pseudoinverse inverts (EIGEN_FLOOR: a Gram matrix's
#: eigenvalues are exact to about 1e3 eps of the largest); the tolerances of the constraint
#: stage and of the braking speed's root search, which their Python references share


#: the limit that set a bound of the compiled acceleration/jerk stage (its ``SM_*_BY`` parts)
LIMIT_NAMES = {L_POSITION: "position", L_VELOCITY: "velocity", L_ACCELERATION: "acceleration",
               L_JERK: "jerk"}


class Layout:
    """Offsets of the parts of ``work`` for m task rows, n joints and c position-limited
    joints, and views on them: the header (parameters, results), the rows' weights and gains,
    the joint mask, the position box (q and v indices, lower and upper limits, return speeds),
    the inverse speed limits, an extra joint velocity (the escape's), the clamped joints of the
    last step, with ``smooth`` the compiled acceleration/jerk stage's part (its motion state,
    limits and the last step's boxes: :meth:`smooth_part`), and the scratch space (the
    clamping's vectors, then the methods')."""

    def __init__(self, m: int, n: int, c: int, smooth: bool = False):
        self.m, self.n, self.c = m, n, c
        self.rows = HEADER
        self.mask = self.rows + 2 * m
        self.box = self.mask + n
        self.speed = self.box + 5 * c
        self.extra = self.speed + n
        # the held joints of the last step, then the saturation's scratch (bounds, candidates,
        # the re-solve's task velocity, the rank test's Gram matrix)
        self.clamped = self.extra + n
        self.smooth = self.clamped + 13 * n + m + m * m if smooth else 0
        self.scratch = (self.smooth + (SMOOTH_SIZE - 1) * n + m if smooth
                        else self.clamped + 13 * n + m + m * m)
        p = min(m, n)
        self.size = self.scratch + 4 * m + 6 * n + 3 * p * p

    def allocate(self) -> np.ndarray:
        """A zeroed ``work`` vector with the offsets written into their slots."""
        work = np.zeros(self.size)
        work[P_ROWS], work[P_MASK], work[P_BOX] = self.rows, self.mask, self.box
        work[P_BOX_COUNT], work[P_SPEED], work[P_SCRATCH] = self.c, self.speed, self.scratch
        work[P_EXTRA], work[P_CLAMPED] = self.extra, self.clamped
        work[P_SMOOTH] = self.smooth  # 0: no compiled acceleration/jerk stage
        work[P_STALL_RUN], work[P_STALL_WAIT] = -1.0, np.inf  # no stall counted yet
        return work

    def info(self, work: np.ndarray) -> np.ndarray:
        return work[INFO:INFO + INFO_SIZE]

    def sqrt_weight(self, work: np.ndarray) -> np.ndarray:
        return work[self.rows:self.rows + self.m]

    def gains(self, work: np.ndarray) -> np.ndarray:
        return work[self.rows + self.m:self.rows + 2 * self.m]

    def joint_mask(self, work: np.ndarray) -> np.ndarray:
        return work[self.mask:self.mask + self.n]

    def box_part(self, work: np.ndarray, k: int) -> np.ndarray:
        """Part ``k`` of the limit box: 0 q indices, 1 v indices, 2 lower, 3 upper, 4 the
        speed (rad/s, m/s) at which a joint outside its range returns."""
        start = self.box + k * self.c
        return work[start:start + self.c]

    def inverse_speeds(self, work: np.ndarray) -> np.ndarray:
        """1 / v_max per joint (0 where there is no limit)."""
        return work[self.speed:self.speed + self.n]

    def extra_velocity(self, work: np.ndarray) -> np.ndarray:
        """A joint velocity added to the method's (the escape's; rad/s, m/s)."""
        return work[self.extra:self.extra + self.n]

    def clamped_joints(self, work: np.ndarray) -> np.ndarray:
        """1 for the joints the last step held at a position or speed bound."""
        return work[self.clamped:self.clamped + self.n]

    def smooth_part(self, work: np.ndarray, part: int) -> np.ndarray:
        """Part ``part`` (an ``SM_*`` name) of the acceleration/jerk stage's space, (n,) (the
        saved gains ``SM_GAINS``: (m,)): the previous velocity and acceleration (the state),
        the acceleration, jerk and jerk-speed limits, the position braking's limits, the last
        step's hard and smoothness boxes and the limits that set them (``L_*`` codes, -1: none),
        its velocity before and after smoothing (rad/s), and 1 where the hard box won."""
        if not self.smooth:
            raise ValueError("this layout has no acceleration/jerk stage "
                             "(Layout(..., smooth=True))")
        start = self.smooth + part * self.n
        return work[start:start + (self.m if part == SM_GAINS else self.n)]

