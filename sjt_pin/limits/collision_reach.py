"""How far the joints can carry the collision limit's geometry: each joint's kind and the
extent of its own motion over its position range (what the levers of the broad phase's skip
add up), and the map from mimic joints' velocities to the model's."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin


def joint_translates(kind: str) -> bool:
    """Whether a joint of this ``shortname()`` translates (its coordinates move points by at
    least a metre per unit)."""
    return any(t in kind for t in ("Prismatic", "FreeFlyer", "Planar", "Translation",
                                   "JointModelP"))


#: joints (``shortname()``) whose motion only turns their frame about its origin
_TURNS = ("JointModelR", "JointModelSpherical", "JointModelUniversal")


def joint_extents(model: pin.Model, mimics: Sequence = ()
             ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Per joint: its kind (``shortname()``; a mimic joint's is the kind of the joint it
    follows) and how far (m) its own motion can carry its frame's origin over its position
    range: 0 for joints that only turn, the largest translation in the box of the URDF limits
    for prismatic, translation, planar and free-flyer joints (``inf`` where a limit is not
    finite, and for any other kind); and the box ``lower <= q <= upper`` (nq,) those extents
    hold in (``-inf``/``inf`` for coordinates they do not depend on, a root joint's among them:
    the levers add a joint's extent only to the joints above it)."""
    lower = np.full(model.nq, -np.inf)
    upper = np.full(model.nq, np.inf)
    kinds = [model.joints[j].shortname() for j in range(model.njoints)]
    extent = np.zeros(model.njoints)
    follows = {model.getJointId(m.joint): m for m in mimics}
    for j in range(1, model.njoints):
        relation = follows.get(j)
        leader = model.getJointId(relation.mimicked) if relation is not None else j
        kind = kinds[leader]
        kinds[j] = kind
        if kind.startswith(_TURNS):
            continue
        if kind.startswith(("JointModelP", "JointModelTranslation", "JointModelFreeFlyer")):
            count = 2 if "Planar" in kind else (1 if kind.startswith("JointModelP") else 3)
        else:
            extent[j] = np.inf  # helical, composite, ...: not bounded here
            continue
        start = model.idx_qs[leader]
        lo = np.array(model.lowerPositionLimit[start:start + count], dtype=float)
        hi = np.array(model.upperPositionLimit[start:start + count], dtype=float)
        if relation is not None:  # q[j] = multiplier q[leader] + offset
            ends = relation.multiplier * np.array([lo, hi]) + relation.offset
            far = np.abs(ends).max(axis=0)
        else:
            far = np.maximum(np.abs(lo), np.abs(hi))
        finite = bool(np.all(np.isfinite(far)) and np.all(far < 1e10))
        extent[j] = float(np.linalg.norm(far)) if finite else np.inf
        if finite and model.parents[j] > 0:  # (a root joint's extent moves no joint's origin:
            # a free-flying base outside its position box keeps the bounds)
            lower[start:start + count], upper[start:start + count] = lo, hi
    return kinds, extent, lower, upper


def mimic_map(model: pin.Model, mimic_joints) -> np.ndarray | None:
    """The (nvExtended, nv) matrix from the velocity of every joint coordinate, mimic joints'
    included, to the model's velocity coordinates (a mimic joint's column adds, times its
    multiplier, to the one it follows); ``None`` without mimic joints."""
    if model.nvExtended == model.nv:
        return None
    G = np.zeros((model.nvExtended, model.nv))
    for j in range(1, model.njoints):
        for k in range(model.nvs[j]):
            G[model.idx_vExtendeds[j] + k, model.idx_vs[j] + k] = 1.0
    for mimic in mimic_joints:
        follower, leader = model.getJointId(mimic.joint), model.getJointId(mimic.mimicked)
        G[model.idx_vExtendeds[follower], model.idx_vs[leader]] = mimic.multiplier
    return G
