"""The options every solver takes, declared once.

:class:`SolverOptions` is the one place a solver option lives: its name, default, type and
documentation. :class:`~sjt_pin.solver.Solver` and the four public solvers take them as keyword
arguments (``SJTSolver(robot, dt=1e-3, posture=...)``) and check them here, so adding an option
is one field below (and the code that uses it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class SolverOptions:
    """
    Common arguments (keyword-only):
        gain: K in 1/s: a number (K = k I), one number per task row, ``"auto"`` (the default:
            ``1 / (dt lambda_hat)`` at every step, lambda_hat >= lambda_max(J M), so the
            fastest mode of the loop settles in one step, at half the stability bound; see
            :mod:`sjt_pin.gains`) or a :class:`~sjt_pin.gains.Gain`.
        dt: control period in s (the integration step), > 0.
        task: a :class:`~sjt_pin.Task` (default: ``PoseTask()`` on the end effector), a list
            of tasks, or a ``{frame: task}`` mapping; with several tasks ``step`` takes
            ``{frame: target}`` mappings.
        posture: a :class:`~sjt_pin.PostureTask` stacked under the tasks (redundant arms).
        pose_length: the characteristic length L (m) of the pose task made when ``task`` is
            ``None``: ``PoseTask(length=pose_length)``; ``None`` for the robot's own (see
            :class:`~sjt_pin.PoseTask`).
        position_limits: keep 1-DoF joints within their URDF position limits (default: on
            when the URDF has them).
        velocity_limits: ``True``/``None`` (the URDF's speed limits, the default), ``False``
            (none), or an (nv,) array in rad/s or m/s (``inf`` for none). With the default and
            ``acceleration_limits``, a revolute joint the URDF gives no speed limit takes the
            largest one its other revolute joints have (docs/limits.md).
        acceleration_limits: joint acceleration limits (rad/s^2 or m/s^2; a number or one
            per velocity coordinate, ``inf`` for none; default ``None``: URDFs have none).
        jerk_limits: joint jerk limits (rad/s^3 or m/s^3; needs ``acceleration_limits``).
        limits: further :class:`~sjt_pin.limits.Limit` objects for the constraint stage (see
            docs/extending.md).
        escape: add a smooth escape velocity at the saddles of exactly singular
            configurations (every built-in method; default True; see :mod:`sjt_pin.escape`).
        check_stability: warn once (:class:`~sjt_pin.GainWarning`) when a fixed gain exceeds
            the stability bound ``2 / (dt lambda_max(J M))`` at the current configuration
            (:mod:`sjt_pin.stability`).

    With acceleration or jerk limits the solver keeps the velocity and acceleration it
    commanded last as its state (a run starts from rest); ``reset()`` returns to rest. The
    state belongs to the command stream, not to the ``q`` passed in: feeding back a measured
    ``q`` near the last output is fine; after a jump of the robot elsewhere, call ``reset()``.
    """

    gain: Any = "auto"
    dt: float = 1e-3
    task: Any = None
    posture: Any = None
    pose_length: float | None = None
    position_limits: bool | None = None
    velocity_limits: Any = None
    acceleration_limits: Any = None
    jerk_limits: Any = None
    limits: Sequence[Any] = ()
    escape: bool = True
    check_stability: bool = True

    @classmethod
    def of(cls, owner: str, options: Mapping[str, Any]) -> SolverOptions:
        """The options in ``options``; an unknown name raises ``TypeError`` naming
        ``owner`` (the solver's class) and the options it takes."""
        known = {field.name for field in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise TypeError(f"{owner} got unexpected keyword argument(s) {unknown}; its common "
                            f"options are {sorted(known)}")
        return cls(**options)

    def keywords(self) -> dict[str, Any]:
        """The options as keyword arguments (the objects themselves, not copies)."""
        return {field.name: getattr(self, field.name) for field in dataclasses.fields(self)}

    def replace(self, **changes: Any) -> SolverOptions:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)
