"""sjt-pin: scaled Jacobian transpose (SJT) differential inverse kinematics on Pinocchio.

The method is Lee, Yim and Choi's scaled Jacobian transpose: ``q_dot = D(q) J^T (x_dot_d + K e)``
with ``D = diag(1 / (J_i^T J_i))``; the pseudoinverse, damped least-squares and plain Jacobian
transpose baselines share the same interface.
"""

from .batch import BatchError, BatchPart, solve_chunks, solve_many
from .exceptions import ConcurrentStepError, FrameNotFound, GainWarning, URDFError
from .gains import AutoGain, FixedGain, Gain
from .ik import IKResult
from .kinematics import Kinematics
from .limits import CollisionLimit, SupportLimit, convex_parts
from .options import SolverOptions
from .reach import ReachMap, reachability
from .robot import Robot
from .solver import Solver
from .solvers import DLSSolver, JPSolver, JTSolver, SJTSolver, make_solver
from .step_info import StepInfo
from .tasks import (
    CoMTask,
    ContactTask,
    OrientationTask,
    PoseTask,
    PositionTask,
    PostureTask,
    RelativePoseTask,
    Task,
)
from .tracking import TrackingLog, track
from .trajectories import Circle, Line, PoseInterpolation, Trajectory

#: the base class of the solvers, under its former name
DifferentialIKSolver = Solver

__all__ = [
    "AutoGain",
    "BatchError",
    "BatchPart",
    "Circle",
    "CoMTask",
    "CollisionLimit",
    "ContactTask",
    "DLSSolver",
    "DifferentialIKSolver",
    "FixedGain",
    "FrameNotFound",
    "Gain",
    "ConcurrentStepError",
    "GainWarning",
    "IKResult",
    "JPSolver",
    "JTSolver",
    "Kinematics",
    "Line",
    "OrientationTask",
    "PoseInterpolation",
    "PoseTask",
    "PositionTask",
    "PostureTask",
    "ReachMap",
    "RelativePoseTask",
    "Robot",
    "SJTSolver",
    "Solver",
    "SolverOptions",
    "SupportLimit",
    "StepInfo",
    "Task",
    "Trajectory",
    "TrackingLog",
    "URDFError",
    "convex_parts",
    "make_solver",
    "reachability",
    "solve_chunks",
    "solve_many",
    "track",
]
__version__ = "0.3.0"
