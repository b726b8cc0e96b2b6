"""The limit protocol: linear inequalities on the joint velocity of one step.

A limit does not change a step itself. It says what joint velocities ``q_dot`` (nv,; rad/s or
m/s per velocity coordinate) are admissible at the step's configuration, in one of two shapes
(the shapes of pink's ``compute_qp_inequalities(configuration, dt)``):

- **bounds** on each velocity coordinate, ``lower <= q_dot <= upper`` (box rows: position,
  speed, acceleration and jerk limits, a joint band), from :meth:`Limit.bounds`;
- **general rows** ``A q_dot <= b`` computed from the step's
  :class:`~sjt_pin.kinematics.Kinematics` (a workspace bound, a collision damper), from
  :meth:`Limit.rows`.

The solver's constraint stage (:mod:`sjt_pin.constraints`) intersects every limit's
inequalities and enforces them after the method, whatever the method: joints that reach a
bound are held there and the others take over the task; a task that cannot be met at all is
scaled down along its own direction. A new limit is one subclass; see the README's "Extend it".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import Kinematics


@dataclass
class Motion:
    """The state a limit may read besides the kinematics: the configuration ``q`` (nq,), the
    velocity ``dq`` (nv,, rad/s or m/s) and acceleration ``ddq`` (nv,, rad/s^2 or m/s^2) the
    solver commanded in its previous step (zero after construction or ``reset()``), the
    control period ``dt`` (s), and the solver's joint acceleration and jerk limits (nv,;
    rad/s^2 or m/s^2, rad/s^3 or m/s^3; ``None`` without them): a limit whose rows close a
    distance bounds the closing speed by what those accelerations can still stop. And the
    solver's speed limits (nv,; rad/s or m/s, ``inf`` where none, 0 for a joint it does not
    move; ``None`` outside a solver's step, as in ``solve()``'s iterations)."""

    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    dt: float
    acceleration_limits: np.ndarray | None = None
    jerk_limits: np.ndarray | None = None
    velocity_limits: np.ndarray | None = None


class Limit:
    """A limit of the constraint stage. Override :meth:`bounds`, :meth:`rows` or both.

    Attributes:
        name: how :class:`~sjt_pin.StepInfo` names the limit when it is active.
        hard: ``True`` for limits the stage never gives up (positions, speeds, collisions);
            ``False`` for smoothness limits (acceleration, jerk), which yield to the hard ones
            when both cannot hold (a start outside the position range, limits changed between
            steps).
        uses_motion: whether :meth:`bounds` or :meth:`rows` read ``motion.dq`` or
            ``motion.ddq``; the solver keeps them up to date (a few microseconds a step) only
            when one of its limits does.
        yields_first: for a smoothness limit, whether it gives way to the other smoothness
            limits where they contradict each other (jerk: an acceleration beyond its limit,
            which collision rows may ask for, cannot return within one step of the jerk
            limit, so the acceleration limit's bound wins); where none or both yield, the
            middle of the two bounds.
    """

    name: str = "limit"
    hard: bool = True
    uses_motion: bool = True
    yields_first: bool = False

    def bounds(self, kinematics: Kinematics, motion: Motion
               ) -> tuple[np.ndarray, np.ndarray] | None:
        """``(lower, upper)`` (nv,) bounds on this step's joint velocity (rad/s or m/s;
        ``-inf``/``inf`` where this limit says nothing), or ``None`` when it says nothing."""
        return None

    def rows(self, kinematics: Kinematics, motion: Motion
             ) -> tuple[np.ndarray, np.ndarray] | None:
        """``(A, b)`` with ``A q_dot <= b`` (A: (k, nv), b: (k,)) at this step's configuration,
        or ``None`` when no row applies (e.g. nothing within a collision's influence)."""
        return None

    def speed_caps(self, dt: float) -> np.ndarray | None:
        """Speeds (nv,; rad/s or m/s, ``inf`` where none) this limit's :meth:`bounds` never go
        below at period ``dt`` (s) and that may bound every step without changing what it
        admits; ``None`` (the default) for none. A solver whose kernel holds its speed limits
        holds these with them, so that a step they cut is saturated there (joints held at
        their caps, the others taking over the task) instead of by the whole stage in Python,
        and does not ask for :meth:`bounds` then (a step within the caps meets them);
        :class:`~sjt_pin.StepInfo` names this limit where they bind."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
