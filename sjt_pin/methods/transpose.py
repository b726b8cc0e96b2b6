"""What JT and SJT share: gradient-type updates and the choice of feed-forward."""

from __future__ import annotations

from .. import kernels
from ..tasks import OrientationTask, PoseTask
from ..validation import positive, real_number
from .base import Method

#: the feed-forward and feedback forms of the transpose methods
FORMS = ("damped", "transpose")
#: the squared column norm below which a joint counts as not moving the tasks (task units^2)
COLUMN_TOL = 1e-10
#: Levenberg-Marquardt weight of the damped feedback: its damping is mu^2 + LM_WEIGHT |e_w|
#: sqrt(max alpha), a bound of the curvature of 1/2 |e_w|^2 on the unit-norm columns that the
#: linear model leaves out (unit-free); the same term bounds the transpose feedback's gain.
LM_WEIGHT = 1.0
#: ... for SJT when every target row is a pose or orientation row. A joint's second derivative
#: of the angular rows vanishes (w_j x w_j = 0) and that of the linear rows is its lever arm
#: rho_j, so on the unit-norm columns the curvature along joint j is at most
#: |e_w| rho_j / (rho_j^2 + L^2) <= |e_w| / (2 L), half of |e_w| sqrt(max alpha) when the
#: wrist's lever is short. Position rows keep 1: there rho_j / max(rho_j^2, l^2) reaches 1 / l.
#: With 1, a redundant arm at a target it cannot reach creeps along its flattest direction
#: (Baxter's arm: 3.7e-3 rad/s after 5 s); with 0.5 it rests (5e-4), and the tracking near
#: singularities improves (UR5's wrist at 2 ms: 0.011 -> 0.0044).
POSE_LM_WEIGHT = 0.5
#: mu of the damped feed-forward (dimensionless: the columns it solves on have unit norm).
FF_DAMPING = 0.01
#: the default floor l under the column norms, as a fraction of the tasks' characteristic
#: length (:func:`~sjt_pin.tasks.pose.tasks_length`)
FLOOR = 0.2


class TransposeMethod(Method):
    """A Jacobian-transpose-type mapping ``S J^T`` (S = I for JT, D for SJT).

    Args:
        feedforward: ``"damped"``: the desired velocity through
            ``S J^T (J S J^T + mu^2 I)^-1`` — a least-squares solve on the columns
            ``J sqrt(S)`` (of unit norm for SJT: unit-free), damped by ``ff_damping`` near
            singularities — while the feedback keeps ``S J^T K e``; ``"transpose"``: through
            ``S J^T`` like the feedback, exactly the paper's eq. (10) / (21).
        feedback: ``"transpose"``: ``S J^T K e`` (eq. 10, 21); ``"damped"``: the feedback goes
            through the damped solve too, ``S J^T (J S J^T + lambda I)^-1 (x_dot_d + K e)``,
            ``lambda = mu^2 + w |e_w| sqrt(max alpha)`` — the damped least squares of the
            unit-norm columns, with a Levenberg-Marquardt term that grows with the error (w:
            ``LM_WEIGHT``, or ``POSE_LM_WEIGHT`` for SJT on pose and orientation rows only;
            needs ``feedforward="damped"``).
        ff_damping: mu of the damped solve (dimensionless, > 0).
        column_tol: squared column norm (task units^2) below which a joint counts as not moving
            the tasks (alpha_i = 0 instead of a division by almost zero).
        length: the floor l (m) under the column norms: ``alpha_i = 1 / max(J_i^T W J_i,
            l^2)``; ``None``: ``FLOOR`` times the characteristic length of the solver's tasks
            (set by :meth:`adapt`), so that it follows the robot's size and length unit.
    """

    stalls = True
    scaled = False

    def __init__(self, feedforward: str = "damped", ff_damping: float = FF_DAMPING,
                 column_tol: float = COLUMN_TOL, length: float | None = 0.0,
                 feedback: str = "transpose"):
        if feedforward not in FORMS:
            raise ValueError(f"feedforward must be one of {sorted(FORMS)}, got {feedforward!r}")
        if feedback not in FORMS:
            raise ValueError(f"feedback must be one of {sorted(FORMS)}, got {feedback!r}")
        if feedback == "damped" and feedforward != "damped":
            raise ValueError("feedback='damped' sends the feed-forward through the damped solve "
                             "too: it needs feedforward='damped'")
        self.feedforward = feedforward
        self.feedback = feedback
        #: the Levenberg-Marquardt weight (see :meth:`adapt`)
        self.lm_weight = LM_WEIGHT
        self.ff_damping = positive(ff_damping, "ff_damping")
        self.column_tol = positive(column_tol, "column_tol", "task units squared")
        #: whether ``length`` follows the tasks' characteristic length (see :meth:`adapt`)
        self.relative = length is None
        self.length = 0.0 if length is None else real_number(length, "length", "m")
        if not 0.0 <= self.length < float("inf"):
            raise ValueError(f"length must be a finite number >= 0 (m) or None, got {length!r}")

    def adapt(self, tasks, length):
        if self.relative:
            self.length = FLOOR * length
        rotational = all(isinstance(t, (PoseTask, OrientationTask)) for t in tasks)
        self.lm_weight = POSE_LM_WEIGHT if self.scaled and rotational and tasks else LM_WEIGHT

    def parameters(self) -> kernels.MethodParameters:
        p = kernels.MethodParameters()
        p.family = kernels.Family.transpose
        p.scaled = self.scaled
        p.damped_feedback = self.feedback == "damped"
        p.damped_feedforward = self.feedforward == "damped"
        p.mu = self.ff_damping
        p.column_tol = self.column_tol
        p.length2 = self.length ** 2
        p.lm = self.lm_weight
        return p

    def bound(self, n_chain):
        return 1.0 if self.feedback == "damped" else None

    def __repr__(self):
        return (f"{type(self).__name__}(feedforward={self.feedforward!r}, "
                f"feedback={self.feedback!r})")
