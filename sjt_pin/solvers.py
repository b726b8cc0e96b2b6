"""The four CLIK solvers of the paper — SJT, JT, JP, DLS — and ``make_solver``.

Each is a :class:`~sjt_pin.solver.Solver` with its :mod:`~sjt_pin.methods` object; they differ
only in the mapping M(J): SJT eq. (21), JT eq. (10), JP eq. (8), DLS (introduction).
"""

from __future__ import annotations

from typing import cast

from .methods import DLS, JP, JT, SJT
from .methods.dls import DLS_DAMPING
from .methods.jp import JP_RCOND
from .methods.transpose import COLUMN_TOL, FF_DAMPING
from .options import SolverOptions
from .robot import Robot
from .solver import Solver

#: the common options' documentation, from the one place they are declared
_COMMON = (SolverOptions.__doc__ or "") + """
    The common options are :class:`~sjt_pin.options.SolverOptions`, declared there once; each
    solver adds its method's.
"""

_TRANSPOSE = """
        feedforward: ``"damped"`` (default): the desired velocity through
            ``D J^T (J D J^T + mu^2 I)^-1`` — a least-squares solve on the unit-norm columns
            ``J sqrt(D)``, unit-free, damped by ``ff_damping`` near singularities;
            ``"transpose"``: through the same transpose as the feedback (the paper's eq. 10/21).
        ff_damping: mu of the damped solve (dimensionless, > 0; default 0.01).
"""

_ERROR_DAMPING = """
        error_damping: w of a Levenberg-Marquardt term that grows with the error: ``{form}``
            with |e_w| the weighted error (m) and L the tasks' characteristic length (m,
            :func:`~sjt_pin.tasks.pose.tasks_length`), Sugihara's error-dependent damping
            ("Solvability-unconcerned inverse kinematics by the Levenberg-Marquardt method",
            IEEE T-RO 2011). With ``K = 1 / dt`` the linear model reaches the target in one
            step; at a target out of reach it is badly wrong and the textbook update oscillates
            at the speed limits, with the term the arm comes to rest; near a reachable target
            the term vanishes. Dimensionless, >= 0; default ``None``: 0.5 when every target row
            is a pose or orientation row, 1 otherwise (as SJT's damped feedback); 0: the
            textbook ``{textbook}``, which the paper's baselines use.
"""


class SJTSolver(Solver):
    __doc__ = """Scaled Jacobian transpose CLIK (eq. 18-22), on SJT's scaling factors.

    ``D = diag(alpha_i)``, ``alpha_i = 1 / (J_i^T W J_i)`` (eq. 18) from the tasks' own
    (weighted, stacked) rows, 0 for joints that do not move them. ``J sqrt(D)`` has unit-norm
    columns, so everything below is unit-free. Three updates, by ``feedback`` and
    ``feedforward``:

    - ``feedback="damped"`` (default): ``q_dot = D J^T (J D J^T + lambda I)^-1 (x_dot_d + K e)``
      — SJT's D in a damped least-squares step, the SJT analogue of what DLS is to JT (it
      tends to D J^T / lambda as the damping grows). ``lambda = mu^2 + w |e_w| sqrt(max
      alpha)``: a Levenberg-Marquardt term that grows with the error relative to the shortest
      lever arm (the curvature that the linear model leaves out; w = 0.5 with pose and
      orientation rows only, 1 otherwise, see ``methods.transpose.POSE_LM_WEIGHT``), so that
      an arm that cannot reach comes to rest; unit-free like the rest. "auto" is
      ``K = 1 / dt``. On the accuracy benchmark its max error is below DLS's (damping 0.05) on
      every path (0.03-0.23x), and it rests at unreachable targets (as DLS and JP do with their
      own error damping, which the textbook forms lack).
    - ``feedback="transpose"``: ``q_dot = D J^T K e`` plus the damped feed-forward: the
      paper's feedback, which corrects slowly along directions J nearly loses.
    - ``feedback="transpose", feedforward="transpose"``: the paper's eq. (21) exactly,
      ``q_dot = D J^T (x_dot_d + K e)``; ``J D J^T`` has eigenvalues in [0, n] (eq. 25).

    SJT's own arguments:
        feedback: ``"damped"`` (default) or ``"transpose"``, see above.
        length: the floor l in m under the column norms, ``alpha_i = 1 / max(J_i^T W J_i,
            l^2)``; default ``None``: a fifth of the tasks' characteristic length
            (:func:`~sjt_pin.tasks.pose.tasks_length`; 0.11 m on Panda, 0.12 m on UR5), so
            that it scales with the robot and its length unit. Pose rows never reach it
            (``J_i^T W J_i >= L^2`` for a revolute joint: eq. 19 with the pose task's length
            L); position-only rows, whose alpha_i nothing else bounds near a joint axis, get
            ``|q_dot_i| <= k |e| / l`` instead. 0 is the paper's eq. (18) exactly.
        column_tol: squared column norm (task units^2) below which a joint counts as not
            moving the tasks at all (alpha_i = 0; default 1e-10).""" + _TRANSPOSE + _COMMON

    def __init__(
        self,
        robot: Robot,
        *,
        feedback: str = "damped",
        feedforward: str = "damped",
        ff_damping: float = FF_DAMPING,
        length: float | None = None,
        column_tol: float = COLUMN_TOL,
        **options,
    ):
        super().__init__(robot, SJT(feedforward, ff_damping, column_tol, length, feedback),
                         **options)


class JTSolver(Solver):
    __doc__ = """Jacobian transpose CLIK, eq. (10)-(11): ``q_dot = J^T (K e) + ff``.

    No singularities; its stable gain shrinks with sigma_max(J)^2, so it depends on the
    robot's size and the length unit ("auto" follows lambda_max(J J^T) at every step). The
    feed-forward is SJT's damped one by default (``feedforward="transpose"``: eq. 10 exactly).

    JT's own arguments:
        column_tol: squared column norm below which a joint's column counts as zero in the
            damped feed-forward (task units^2).""" + _TRANSPOSE + _COMMON

    def __init__(
        self,
        robot: Robot,
        *,
        feedforward: str = "damped",
        ff_damping: float = FF_DAMPING,
        column_tol: float = COLUMN_TOL,
        **options,
    ):
        super().__init__(robot, JT(feedforward, ff_damping, column_tol, None), **options)


class JPSolver(Solver):
    __doc__ = """Jacobian pseudoinverse CLIK, eq. (8)-(9): ``q_dot = J^+ (x_dot_d + K e)``.

    Exact tracking; blows up near singularities. ``"auto"`` is ``K = 1 / dt`` (J J^+ is a
    projector: its eigenvalues are 0 or 1).

    JP's own arguments:
        rcond: singular values below ``rcond sigma_max`` count as zero (at least about 5e-7:
            the kernel works on J J^T).""" + _ERROR_DAMPING.format(
        form="J^T (J J^T + w |e_w| L I)^-1", textbook="J^+") + _COMMON

    def __init__(
        self,
        robot: Robot,
        *,
        rcond: float = JP_RCOND,
        error_damping: float | None = None,
        **options,
    ):
        super().__init__(robot, JP(rcond, error_damping), **options)

    @property
    def rcond(self) -> float:
        return cast(JP, self.method).rcond


class DLSSolver(Solver):
    __doc__ = """Damped least-squares CLIK: ``q_dot = J^T (J J^T + lambda^2 I)^-1 (x_dot_d + K e)``.

    ``"auto"`` is ``K = 1 / dt`` (the loop eigenvalues sigma^2 / (sigma^2 + lambda^2) < 1).

    DLS's own arguments:
        damping: lambda in task units (m for position rows, rad for orientation rows; default
            0.05): larger is more robust near singularities and less accurate.""" + \
        _ERROR_DAMPING.format(form="J^T (J J^T + (lambda^2 + w |e_w| L) I)^-1",
                              textbook="J^T (J J^T + lambda^2 I)^-1") + _COMMON

    def __init__(
        self,
        robot: Robot,
        *,
        damping: float = DLS_DAMPING,
        error_damping: float | None = None,
        **options,
    ):
        super().__init__(robot, DLS(damping, error_damping), **options)

    @property
    def damping(self) -> float:
        return cast(DLS, self.method).damping


SOLVERS: dict[str, type[Solver]] = {
    "sjt": SJTSolver, "jt": JTSolver, "jp": JPSolver, "dls": DLSSolver,
}


def make_solver(name: str, robot: Robot, **kwargs) -> Solver:
    """The solver called ``name`` (``"sjt"``, ``"jt"``, ``"jp"`` or ``"dls"``, any case).

    ``kwargs`` go to its constructor (``gain``, ``dt``, ``task``, ``damping`` for DLS, ...).
    """
    key = str(name).lower()
    if key not in SOLVERS:
        raise ValueError(f"name must be one of {sorted(SOLVERS)}, got {name!r}")
    return SOLVERS[key](robot, **kwargs)
