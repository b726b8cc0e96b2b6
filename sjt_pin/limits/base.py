"""The limit protocol: linear inequalities on the joint velocity of one step.

A limit does not change a step itself. It says what joint velocities ``q_dot`` (nv,; rad/s or
m/s per velocity coordinate) are admissible at the step's configuration, in one of two shapes
(the shapes of pink's ``compute_qp_inequalities(configuration, dt)``):

- **bounds** on each velocity coordinate, ``lower <= q_dot <= upper`` (a joint band), from
  :meth:`Limit.bounds`;
- **general rows** ``A q_dot <= b`` computed from the step's
  :class:`~sjt_pin.kinematics.Kinematics` (a workspace bound, a collision damper), from
  :meth:`Limit.rows`.

The solver's compiled constraint stage intersects them with the built-in limits (position,
speed, acceleration, jerk: :mod:`.position`, :mod:`.velocity`, :mod:`.acceleration`,
:mod:`.jerk`) and enforces them after the method, whatever the method: the method's step
where it is within every limit, else the admissible velocity nearest to it in the method's own
metric — joints at a bound are held there and the others take over the task, and the task's
error still falls wherever some admissible velocity makes it fall. A user's bounds and rows are
hard limits: where they cannot hold together with the acceleration and jerk limits, those
yield. A new limit is one subclass; see the documentation's "Extending".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import Kinematics

#: the share of each joint's acceleration (and jerk) limit a row with room counts on to stop
#: its closing speed within that room (``kernels.stoppable_rows``); the rest is the task's and
#: the other rows'
BRAKING_SHARE = 0.5
#: beside acceleration limits a row that turns or appears eases in at what they allow as long as
#: its room stays above minus this (m) (``kernels.stoppable_rows``)
EASING_SLACK = 5e-4


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
        uses_motion: whether :meth:`bounds` or :meth:`rows` read ``motion.dq`` or
            ``motion.ddq`` (informational: the solver always keeps them).
        brakes_rows: whether :meth:`rows` already cuts the bounds of its rows with
            :meth:`room` to closing speeds the motion's acceleration (and jerk) limits can
            stop within that room (as :class:`~sjt_pin.CollisionLimit` does). Where not
            (the default), the solver does it beside acceleration limits: each such row's
            bound is kept, and lowered ahead of the room so that the arm brakes to it within
            half of those limits (``kernels.stoppable_rows``), never asked to slow faster
            than they allow. ``True`` also says each such bound is a damper of its room
            (``b`` falls with the room, as ``gain * room / dt``): the displacement the arm
            is sent toward under acceleration limits is then bounded along the row by
            ``min(room, b / K)`` (``K`` the feedback's gain) rather than the room alone, and
            an arm at rest against such a row starts only under jerk limits (a bound that is
            a speed cap would send the arm nowhere: leave it ``False``). A row of
            :meth:`needs` (given up) is not braked by the solver.
    """

    name: str = "limit"
    uses_motion: bool = True
    brakes_rows: bool = False

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

    def room(self) -> np.ndarray | None:
        """How far the rows of the last :meth:`rows` let the joints move: ``r`` (k,) with
        ``A d <= r`` for a displacement ``d`` (rad or m; for a distance row its distance minus
        its margin, m), NaN (or inf) for a row that bounds velocity only; ``None`` (the
        default) where the rows bound velocity only. Under acceleration limits, each row's
        bound is lowered to closing speeds the arm can stop within its room (unless
        :attr:`brakes_rows`), and where the displacement the task's feedback asks would break
        a row's room or leave a position range, the arm is sent to the nearest displacement
        within them and so brakes to rest at the constrained minimum of its task error rather
        than sliding along the bound."""
        return None

    def needs(self) -> np.ndarray | None:
        """For the rows of the last :meth:`rows` this limit gives up (no step within the
        solver's limits keeps them, whatever the acceleration and jerk limits yield: a
        collision row whose obstacle comes faster than the arm can retreat), the bound each
        would need, below the bound returned (k,; NaN for every other row); ``None`` (the
        default) where no row is given up. The stage keeps a given-up row's bound only as far
        as the acceleration and jerk limits allow (its best within them, never yielding them
        for it), and ``StepInfo.rows_exceeded`` measures the step against what it needs."""
        return None

    def speed_caps(self, dt: float) -> np.ndarray | None:
        """Speeds (nv,; rad/s or m/s, ``inf`` where none) this limit's :meth:`bounds` never go
        below at period ``dt`` (s), which the solver may hold with its speed limits instead of
        asking :meth:`bounds` every step; ``None`` (the default) for none. A limit with caps
        whose bounds are exactly the caps need not define :meth:`bounds`."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
