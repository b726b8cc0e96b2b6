"""Joint limits in a step: the clamping pass of the joints that would leave their range."""

from __future__ import annotations

from .compile import compiled


@compiled(inline=True)
def clamp_pass(q, step, q_index, v_index, lower, upper, speeds, dt, fixed, fixed_step):
    """Fix the joints that ``q + step`` takes out of ``[lower, upper]``; returns how many.

    ``q_index``, ``v_index`` may be floats (as stored in a solver's ``work``). A fixed joint
    inside its range moves exactly onto the limit. A joint that starts outside (a start
    configuration out of range) is driven back toward the range at ``speeds`` (rad/s or m/s)
    and no further than the limit. ``fixed`` (1.0 where fixed) and ``fixed_step``
    (tangent-indexed) are updated in place.
    """
    count = 0
    for c in range(q_index.shape[0]):
        v = int(v_index[c])
        if fixed[v] != 0.0:
            continue
        qc, lo, hi = q[int(q_index[c])], lower[c], upper[c]
        new = qc + step[v]
        if lo <= qc <= hi:
            if lo <= new <= hi:
                continue
            fixed_step[v] = min(max(new, lo), hi) - qc
        elif qc > hi:
            fixed_step[v] = -min(speeds[c] * dt, qc - hi)
        else:
            fixed_step[v] = min(speeds[c] * dt, lo - qc)
        fixed[v] = 1.0
        count += 1
    return count
