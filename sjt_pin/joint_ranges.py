"""The position range of each 1-DoF joint as the solvers read it from a Pinocchio model.

A URDF ``<limit lower upper>`` on a revolute or prismatic joint is its range, with two readings
fixed here once:

- ``lower == upper`` (other than 0) is a **locked** joint: its range is that single value, and
  the solvers hold it there (a seed elsewhere is brought back);
- ``lower == upper == 0`` — what a ``<limit>`` without ``lower``/``upper`` means, and what CAD
  exporters write for joints meant to turn freely — and values beyond 1e30 (Pinocchio's reading
  of a joint without ``<limit>``) are **no** limit.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

#: position limits beyond this magnitude (rad or m) are no limit
NO_LIMIT = 1e30


def position_ranges(model: pin.Model) -> tuple[np.ndarray, np.ndarray]:
    """The position limits the solvers enforce (nq,): a 1-DoF revolute or prismatic joint's
    URDF limits (a single value for a locked joint); -inf / +inf for every other coordinate
    (continuous joints, a floating base, spherical and planar joints, unlimited joints)."""
    lower, upper = np.full(model.nq, -np.inf), np.full(model.nq, np.inf)
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq != 1 or joint.nv != 1:
            continue  # continuous (cos, sin), floating base, spherical, planar, mimic: none
        i = joint.idx_q
        lo, hi = float(model.lowerPositionLimit[i]), float(model.upperPositionLimit[i])
        if not (abs(lo) < NO_LIMIT and abs(hi) < NO_LIMIT and lo <= hi) or lo == hi == 0.0:
            continue
        lower[i], upper[i] = lo, hi
    return lower, upper


def outside(model: pin.Model, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            mimics: Sequence = ()) -> tuple[str, ...]:
    """Names of the 1-DoF joints whose position in ``q`` lies outside ``[lower, upper]``, then
    of the mimic joints (``mimics``: :class:`~sjt_pin.mimic.MimicJoint` relations as applied)
    whose position by their relation lies outside their own range. A joint that mimic joints
    follow has the range they leave it (``lower``, ``upper`` of the model), so a mimic joint
    out of its range names both."""
    out = (q < lower) | (q > upper)
    if not out.any():
        return ()
    names = [model.names[j] for j in range(1, model.njoints)
             if model.joints[j].nq == 1 and out[model.joints[j].idx_q]]
    for mimic in mimics:
        joint = model.joints[model.getJointId(mimic.mimicked)]
        if joint.nq == 1 and out[joint.idx_q]:
            value = mimic.multiplier * q[joint.idx_q] + mimic.offset
            if not mimic.lower <= value <= mimic.upper:
                names.append(mimic.joint)
    return tuple(names)
