"""sjt-pin: scaled Jacobian transpose (SJT) differential inverse kinematics on Pinocchio.

The method is Lee, Yim and Choi's scaled Jacobian transpose: ``q_dot = D(q) J^T (x_dot_d + K e)``
with ``D = diag(1 / (J_i^T J_i))``; the pseudoinverse, damped least-squares and plain Jacobian
transpose baselines share the same interface.
"""

from .exceptions import FrameNotFound, GainWarning, URDFError
from .methods import DLSSolver, JPSolver, JTSolver, SJTSolver, make_solver
from .robot import Robot
from .solve import IKResult
from .solvers import DifferentialIKSolver, StepInfo
from .tasks import OrientationTask, PoseTask, PositionTask, PostureTask, Task
from .tracking import TrackingLog, track
from .trajectories import Circle, Line, PoseInterpolation, Trajectory

__all__ = [
    "Circle",
    "DLSSolver",
    "DifferentialIKSolver",
    "FrameNotFound",
    "GainWarning",
    "IKResult",
    "JPSolver",
    "JTSolver",
    "Line",
    "OrientationTask",
    "PoseInterpolation",
    "PoseTask",
    "PositionTask",
    "PostureTask",
    "Robot",
    "SJTSolver",
    "StepInfo",
    "Task",
    "Trajectory",
    "TrackingLog",
    "URDFError",
    "make_solver",
    "track",
]
__version__ = "0.1.0"
