"""When is a closed-loop run stable, and what is the largest stable gain (by simulation)?

Used by the paper's gain sweeps (:mod:`sjt_pin.paper.experiments`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..tracking import TrackingLog


def stability(log: TrackingLog, oscillation_tol: float = 1e-4,
              speed_bound: float = 100.0) -> tuple[bool, str]:
    """Whether a run is stable, and if not why.

    Unstable means any of:

    - the run diverged (non-finite state or half a turn in one step, see
      :func:`~sjt_pin.tracking.track`);
    - a joint flails: some ``|q_dot_i|`` exceeds ``speed_bound`` (rad/s or m/s);
    - a period-2 oscillation does not die out: the alternating part of the error,
      ``|e[k+1] - 2 e[k] + e[k-1]| / 4``, averaged over the last 10 % of the run, is above
      ``oscillation_tol`` (task units) and at least half its average over the 10 % before.

    There is no bound on the error itself: a revolute arm's error is bounded by its geometry,
    so an unstable loop shows as flailing or oscillation, while a stable loop with a low gain
    may lag far behind its path and still be stable.
    """
    if log.diverged:
        return False, log.reason
    speed = log.max_joint_speed
    if speed > speed_bound:
        return False, f"a joint reached {speed:.3g} rad/s"
    e = log.error
    if len(e) < 6:
        return True, ""
    alternating = np.linalg.norm(e[2:] - 2.0 * e[1:-1] + e[:-2], axis=1) / 4.0
    window = max(alternating.size // 10, 2)
    last, before = alternating[-window:].mean(), alternating[-2 * window:-window].mean()
    if last > oscillation_tol and last >= 0.5 * before:
        return False, f"period-2 oscillation of amplitude {last:.3g} that does not die out"
    return True, ""


def largest_stable(is_stable: Callable[[float], bool], low: float, high: float,
                   rtol: float = 0.005) -> float:
    """Bisect (geometrically) between a stable gain ``low`` and an unstable ``high``.

    Returns the largest gain found stable, to relative width ``rtol``, or 0 when ``low`` itself
    is unstable. Assumes one crossing: stable below some gain, unstable above.
    """
    if not is_stable(low):
        return 0.0
    while high - low > rtol * high:
        mid = np.sqrt(low * high)
        if is_stable(mid):
            low = mid
        else:
            high = mid
    return low
