"""Tasks: blocks of rows of the CLIK law, one class per file (see :mod:`.base`)."""

from .base import Task
from .com import CoMTask
from .contact import ContactTask
from .orientation import OrientationTask
from .pose import PoseTask
from .position import PositionTask
from .posture import PostureTask
from .relative_pose import RelativePoseTask

__all__ = ["CoMTask", "ContactTask", "OrientationTask", "PoseTask", "PositionTask", "PostureTask",
           "RelativePoseTask", "Task"]
