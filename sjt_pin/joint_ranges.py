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

import threading
import warnings
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


def at_limits(model: pin.Model, frame_id: int, q: np.ndarray, lower_limits: np.ndarray,
              upper_limits: np.ndarray) -> list[str]:
    """The 1-DoF joints on the chain that moves frame ``frame_id`` which ``q`` puts exactly on a
    limit of their range (``lower_limits``, ``upper_limits``; a single value is no range), each
    as ``"name (lower)"`` or ``"name (upper)"``."""
    chain = model.supports[model.frames[frame_id].parentJoint]
    at = []
    for j in chain[1:]:
        joint = model.joints[j]
        if joint.nq != 1:
            continue
        i = joint.idx_q
        lower, upper = lower_limits[i], upper_limits[i]
        if not lower < upper:
            continue
        if abs(q[i] - lower) <= 1e-9 * max(1.0, abs(lower)):
            at.append(f"{model.names[j]} (lower)")
        elif abs(q[i] - upper) <= 1e-9 * max(1.0, abs(upper)):
            at.append(f"{model.names[j]} (upper)")
    return at


def clipped_q0(model: pin.Model, q0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
               robot_name: str) -> np.ndarray:
    """``q0`` clipped into the position limits, with a warning naming the joints moved."""
    outside = (q0 < lower) | (q0 > upper)
    if not outside.any():
        return q0.copy()
    names = [model.names[j] for j in range(1, model.njoints)
             if model.joints[j].nq == 1 and outside[model.joints[j].idx_q]]
    warnings.warn(f"{robot_name}: the reference configuration q0 puts {names} outside their "
                  f"URDF limits; q0 is clipped into range", UserWarning, stacklevel=4)
    return np.clip(q0, lower, upper)


#: guards Pinocchio's global random generator (seeded and drawn by random_within)
_PINOCCHIO_RNG = threading.Lock()


def random_within(model: pin.Model, lower_limits: np.ndarray, upper_limits: np.ndarray,
                  rng: np.random.Generator | None) -> np.ndarray:
    """A configuration drawn uniformly within the position limits (``[-pi, pi]`` if none),
    reproducibly from ``rng`` (it reseeds Pinocchio's global generator, under a lock)."""
    rng = np.random.default_rng() if rng is None else rng
    lower = np.where(np.isfinite(lower_limits), lower_limits, -np.pi)
    upper = np.where(np.isfinite(upper_limits), upper_limits, np.pi)
    with _PINOCCHIO_RNG:  # Pinocchio draws from one global generator, seeded from rng
        pin.seed(int(rng.integers(2**31 - 1)))
        return pin.randomConfiguration(model, lower, upper)
