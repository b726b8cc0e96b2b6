"""What JP and DLS share: a least-squares solve in task space, damped by the error.

The auto gain ``K = 1 / dt`` makes the linear model reach the target in one step. Where the
target cannot be reached the model is badly wrong (the arm is at the workspace's boundary, the
error is large and J loses the direction toward it), and the textbook update overshoots back
and forth at the speed limits instead of resting (Panda, a target 0.8 m beyond reach: 0.94
rad/s RMS). So both add a Levenberg-Marquardt term that grows with the error to the damping of
the solve, ``J^T (J J^T + (lambda^2 + w |e_w| L) I)^-1`` (lambda = 0 for JP), as Sugihara's
error-dependent damping for IK ("Solvability-unconcerned inverse kinematics by the
Levenberg-Marquardt method", IEEE T-RO 27(5), 2011, which damps by ``1/2 e^T W_E e + w_N``)
and SJT's damped feedback do. Its units: the rows are weighted so that ``e_w`` is in m (L on
the angular rows), ``J J^T`` is in m^2, and ``|e_w| L`` bounds the curvature term
``sum_i e_w,i d^2 e_w,i / dq^2`` that the linear model leaves out when the joints' lever arms
are at most L (the tasks' characteristic length, :func:`~sjt_pin.tasks.pose.tasks_length`).
Near a reachable target |e_w| is small and the term vanishes, so tracking keeps the textbook
update's accuracy.

w by measurement (a target 0.05, 0.3 or 2 m beyond reach, from q0 and random configurations,
8 s at 1 kHz; UR3, UR5, UR10, Panda, xArm7, Kinova, Bravo 7, Z1): with pose rows only, 0.5 rests
everywhere (RMS speed over the last second below 1e-7 rad/s), the same ``POSE_LM_WEIGHT`` as
SJT's (the angular rows' second derivatives vanish); with position rows 0.5 oscillates at the
speed limits (UR3, UR5, Panda, xArm7, Z1) and 1 rests (Kinova's position-only runs still creep
at 2e-3-2e-2 rad/s after 8 s, SJT's at 2e-2-0.4). A larger w rests too but slows what the
error term slows: the lag along nearly lost directions (UR5's wrist path at 2 ms, DLS: max
error 0.017 textbook, 0.022 with 0.5, 0.029 with 1) and the exit from an exact saddle.
"""

from __future__ import annotations

import math

from .. import kernels
from ..tasks import OrientationTask, PoseTask
from ..validation import real_number
from .base import Method
from .transpose import LM_WEIGHT, POSE_LM_WEIGHT


class LeastSquaresMethod(Method):
    """``M = J^T (J J^T + (lambda^2 + w |e_w| L) I)^-1`` (lambda = 0: the pseudoinverse, whose
    exactly lost directions stay dropped): the loop eigenvalues are at most 1, so "auto" is
    ``k = c / dt``.

    Args:
        error_damping: w of the Levenberg-Marquardt term ``w |e_w| L`` (dimensionless, >= 0),
            see the module's docstring; ``None`` (default): 0.5 when every target row is a
            pose or orientation row, 1 otherwise (set by :meth:`adapt`); 0: the textbook
            update (the paper's baselines).
    """

    damping = 0.0
    rcond = 1e-12
    stalls = True

    def __init__(self, error_damping: float | None = None):
        if error_damping is not None:
            w = real_number(error_damping, "error_damping")
            if not 0.0 <= w < math.inf:
                raise ValueError(f"error_damping must be a finite number >= 0 (0: the textbook "
                                 f"update) or None, got {error_damping!r}")
            error_damping = w
        self.error_damping = error_damping
        #: the w in use (set by :meth:`adapt` when ``error_damping`` is ``None``)
        self.lm_weight = LM_WEIGHT if error_damping is None else error_damping
        #: L (m), the characteristic length of the solver's tasks (set by :meth:`adapt`)
        self.length = 1.0

    def adapt(self, tasks, length):
        self.length = length
        if self.error_damping is None:
            rotational = all(isinstance(t, (PoseTask, OrientationTask)) for t in tasks)
            self.lm_weight = POSE_LM_WEIGHT if rotational and tasks else LM_WEIGHT

    def parameters(self) -> kernels.MethodParameters:
        p = kernels.MethodParameters()
        p.family = kernels.Family.least_squares
        p.mu = self.damping
        p.rcond = self.rcond
        p.lm = self.lm_weight * self.length  # w L (m): the kernel multiplies |e_w|
        return p

    def bound(self, n_chain):
        return 1.0
