"""What a :class:`~sjt_pin.solver.Solver`'s step does in Python, off its compiled path: the
first step's warning about joints outside their range that no task moves, the error for a
non-finite step, and the task rows the saddle escape's curvature test evaluates. (A method of
the user's has its matrix called by the compiled step itself, ``kernels.Controller.run``.)"""

from __future__ import annotations

import math
import warnings

import numpy as np

from .exceptions import ConcurrentStepError
from .joint_ranges import outside
from .robot import Robot
from .stack import TaskStack
from .validation import raise_non_finite_targets


def warn_idle_outside(robot: Robot, chain: np.ndarray, q: np.ndarray) -> None:
    """Warn (first step) about joints outside their range that no task moves (``chain``: the
    velocities the tasks move): the step brings a joint back only if a task moves it, so these
    stay where they are (a gripper's finger and the mimic joint that follows it, for
    instance); ``StepInfo.outside_limits`` names them on every step."""
    model = robot.model
    names = outside(model, q, robot.lower_limits, robot.upper_limits, robot.mimic_joints)
    idle = [name for name in names
            if not chain[model.joints[model.getJointId(name)].idx_v]]
    if idle:
        warnings.warn(f"joints {idle} start outside their URDF position range and no task "
                      "moves them: they stay there (stack a PostureTask within the range "
                      "to bring them back)", UserWarning, stacklevel=4)


def weighted_rows(probe: TaskStack, stack: TaskStack, targets, exact: bool):
    """``q -> (J_w, e_w)``: the weighted, masked rows of ``stack``'s first priority level for
    ``targets``, evaluated on ``probe``, a copy of it (the step's buffers stay as they are).
    Only the first level's: the escape acts on the error the method's step lowers. (With the
    posture's rows counted, Panda stretched toward a target out of reach under acceleration
    limits took a settling step back toward the posture every 0.25 s, which the first level
    undid, swinging at up to 0.8 rad/s for good.) A contact's rows and a posture given
    ``priority=0`` are rows of that level, and stay in it; a contact holds the pose the step
    holds now (``held``; after ``release()`` the probe's copy would keep the old one)."""
    begin, end = stack.levels[0][:2]
    sw, mask = stack.sqrt_weight[begin:end], stack.chain
    targets = list(targets)
    for mine, theirs in zip(probe.tasks, stack.tasks, strict=True):
        if hasattr(theirs, "held"):
            mine.held = theirs.held  # type: ignore[attr-defined]

    def rows(q):
        J, e, _ = probe.evaluate(q, targets, None)
        J = probe.step_rows(J, e, exact)  # (the rows the step takes)
        return sw[:, None] * J[begin:end] * mask, sw * e[begin:end]

    return rows


def raise_non_finite(robot: Robot, e_sq: float, q: np.ndarray, targets) -> None:
    """The error for a step whose result is not finite (``e_sq``: its squared error): ``q``,
    the targets or the feed-forward holds NaN or inf."""
    robot.check_q(q)  # names q if it holds NaN or inf
    if not math.isfinite(e_sq):
        raise_non_finite_targets(targets)
    raise ValueError("target_velocity contains NaN or inf (the feed-forward is not finite)")


def refuse_concurrent(name: str) -> None:
    """The error for a second thread that steps a solver (of class ``name``) while a step runs."""
    raise ConcurrentStepError(
        f"{name} is being stepped by another thread: a solver's buffers "
        "and pin.Data are one thread's; give each thread its own solver "
        "(copy.deepcopy(solver) makes one in the same state)")
