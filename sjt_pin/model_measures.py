"""What a robot's Pinocchio model implies, computed once per model: the unit-norm blocks of its
configurations, its speed limits, its reach (and the warning for a target far beyond it), the
memory one ``pin.Data`` of it takes (a model above the budget is refused) and whether it has
the mass a centre of mass needs."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pinocchio as pin

from .validation import UnitBlocks

#: Bytes one ``pin.Data`` may take by default (:meth:`Robot.data_bytes`); a robot whose data
#: would need more is refused (pass ``memory_budget=``), one needing a quarter of it warned.
#: Each thread that queries a robot, and each solver, holds its own ``pin.Data``.
MEMORY_BUDGET = 2e9

#: A target farther from the robot's base than this many times its reach gets a warning.
REACH_FACTOR = 10.0


def velocity_limits(model: pin.Model) -> np.ndarray:
    """The URDF's joint speed limits (nv,), ``+inf`` where it gives none."""
    limit = np.asarray(model.velocityLimit, dtype=float)
    return np.where((limit > 0) & (limit < 1e30), limit, np.inf)


def revolute_velocities(model: pin.Model) -> np.ndarray:
    """(nv,) bool: the velocity coordinates of 1-DoF revolute joints (bounded or continuous,
    along an axis or unaligned): the coordinates in rad/s."""
    out = np.zeros(model.nv, dtype=bool)
    for joint in model.joints[1:]:
        if joint.nv == 1 and joint.shortname().startswith("JointModelR"):
            out[joint.idx_v] = True
    return out


def velocity_names(model: pin.Model) -> list[str]:
    """The name of the joint of each velocity (tangent) index: columns of J, entries of dq."""
    return [model.names[j] for j in range(1, model.njoints) for _ in range(model.joints[j].nv)]


def warn_far_target(position, origin, reach: float, robot_name: str, from_base: bool,
                    name: str) -> None:
    """Warn when ``position`` (m) lies more than :data:`REACH_FACTOR` times ``reach`` from
    ``origin`` (the world's origin, or with ``from_base`` a floating base's position): see
    ``Robot.check_reach``."""
    # math.hypot: no overflow (it scales), NaN and inf pass through, no numpy warning state
    distance = math.hypot(*(np.asarray(position, dtype=float) - origin).tolist())
    # NaN, inf or an overflowing distance: the task error cannot be finite, step() raises
    if np.isfinite(distance) and distance > REACH_FACTOR * reach:
        where = "the origin" if not from_base else "the robot's base"
        warnings.warn(
            f"{name} is {distance:.4g} m from {where}, more than {REACH_FACTOR:g} times "
            f"{robot_name}'s reach ({reach:.3g} m): positions are in m (check its "
            "units: mm or cm by mistake?)", UserWarning, stacklevel=4)


def unit_blocks(model: pin.Model) -> UnitBlocks:
    """The unit-norm blocks of ``model``'s configurations (see :class:`UnitBlocks`)."""
    blocks = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind, first = joint.shortname(), joint.idx_q
        if kind == "JointModelFreeFlyer":
            blocks.append((model.names[j], "quaternion (x, y, z, w)", first + 3, 4))
        elif kind == "JointModelSpherical":
            blocks.append((model.names[j], "quaternion (x, y, z, w)", first, 4))
        elif kind == "JointModelPlanar":
            blocks.append((model.names[j], "(cos, sin) pair", first + 2, 2))
        elif kind.startswith("JointModelRUB") or kind == "JointModelRevoluteUnboundedUnaligned":
            blocks.append((model.names[j], "(cos, sin) pair", first, 2))
    return UnitBlocks(blocks)


def reach(model: pin.Model) -> tuple[float, int | None]:
    """An upper bound of the distance from the robot's base any frame can reach (m): the
    lengths of the joint placements along each chain, plus prismatic ranges; and the index in
    q of a floating base's position (a free flyer at the root: the base is there), else None.
    The reach is ``inf`` with a planar joint, an unlimited prismatic joint or a free flyer
    elsewhere than at the root."""
    length = np.zeros(model.njoints)
    base = None
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind = joint.shortname()
        travel = 0.0
        if joint.nq == 1 and kind.startswith("JointModelP"):
            lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            travel = max(abs(lo), abs(hi)) if hi > lo else np.inf
        elif kind == "JointModelFreeFlyer" and model.parents[j] == 0 and base is None:
            base = joint.idx_q  # distances are then measured from the base's position
        elif kind in ("JointModelFreeFlyer", "JointModelPlanar", "JointModelTranslation"):
            travel = np.inf
        length[j] = (length[model.parents[j]] + travel
                     + float(np.linalg.norm(model.jointPlacements[j].translation)))
    reach = max((length[f.parentJoint] + float(np.linalg.norm(f.placement.translation))
                 for f in model.frames), default=0.0)
    return reach, base


def data_bytes(model: pin.Model) -> int:
    """Estimated bytes of one ``pin.Data``: 30 nv³ + 1100 nv², fitted to Pinocchio 3 on
    serial chains (measured 41 MB at nv = 100, 279 MB at 200, 901 MB at 300)."""
    nv = model.nv
    return int(30 * nv**3 + 1100 * nv**2)


def check_memory(model: pin.Model, label: str, budget: float) -> None:
    """Refuse a model whose ``pin.Data`` would take more than ``budget`` bytes; warn above a
    quarter of it."""
    need = data_bytes(model)
    if need > budget:
        raise ValueError(f"{label}: a pin.Data of this model (nv = {model.nv}) would take about "
                         f"{need / 1e9:.3g} GB, above memory_budget = {budget / 1e9:.3g} GB; "
                         "every thread and solver holds one (pass memory_budget= to allow it)")
    if need > budget / 4:
        warnings.warn(f"{label}: a pin.Data of this model (nv = {model.nv}) takes about "
                      f"{need / 1e9:.3g} GB, and every thread and solver holds one",
                      UserWarning, stacklevel=4)


def check_mass(model: pin.Model, robot_name: str, what: str) -> None:
    """Raise ``ValueError`` where the links of ``model`` have no mass between them (a URDF
    without ``<inertial>`` elements): the centre of mass ``what`` needs is then 0 / 0."""
    total = sum(model.inertias[j].mass for j in range(1, model.njoints))  # (not the world's)
    if not total > 0:
        raise ValueError(f"{what} needs the robot's centre of mass, but the links of "
                         f"{robot_name} have no mass (total {total:g} kg): give them "
                         "<inertial> elements in the URDF")
