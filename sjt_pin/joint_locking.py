"""Joints locked out of a robot's model (``Robot.reduced``): the joint names checked, and
Pinocchio's ``buildReducedModel`` run on the model, or on the model without its mimic joints
where it has some (a joint that follows a locked one is locked with it, the other relations
tied again afterwards); the geometry and the reference configuration follow."""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .exceptions import URDFError
from .mimic import MimicJoint, apply_mimics, joint_values
from .validation import name_list


def locked_ids(model: pin.Model, names: Sequence[str], robot_name: str) -> list[int]:
    """The ids of the joints ``names`` of ``model``; a ``ValueError`` naming close names for a
    joint it does not have."""
    ids = []
    for joint in names:
        if not model.existJointName(joint) or joint == "universe":
            known = [model.names[j] for j in range(1, model.njoints)]
            close = difflib.get_close_matches(joint, known, n=3)
            hint = f"close names: {close}" if close else f"joints: {name_list(known)}"
            raise ValueError(f"locked_joints: {robot_name} has no joint {joint!r}; {hint}")
        ids.append(model.getJointId(joint))
    return ids


class Reduction(NamedTuple):
    """A model with joints locked, and what follows it."""

    model: pin.Model
    visual_model: pin.GeometryModel | None
    collision_model: pin.GeometryModel | None
    unmimicked: pin.Model | None  #: ``model`` before its mimic joints (None without any)
    mimics: list[MimicJoint]  #: the mimic relations that remain
    q0: np.ndarray  #: the reference configuration on ``model``


def reduce_model(model: pin.Model, unmimicked: pin.Model | None, mimics: Sequence[MimicJoint],
                 visual_model: pin.GeometryModel | None,
                 collision_model: pin.GeometryModel | None, names: Sequence[str],
                 ids: list[int], q_ref: np.ndarray, q0: np.ndarray,
                 robot_name: str) -> Reduction:
    """``model`` (its geometry, mimic relations and reference configuration ``q0``) with the
    joints ``names`` (ids ``ids``) locked at their values in ``q_ref``."""
    base, q_base, mimics = model, q_ref, list(mimics)
    if mimics:
        if unmimicked is None:
            raise TypeError(f"robot {robot_name!r} has mimic joints but no model without "
                            "them to reduce (load it with from_urdf or from_example)")
        base = unmimicked
        q_base, ids, mimics = unmimicked_lock(model, base, mimics, names, q_ref)
    geometries = [g for g in (visual_model, collision_model) if g is not None]
    try:
        if geometries:
            reduced, reduced_geometries = pin.buildReducedModel(base, geometries, ids, q_base)
            reduced_geometries = list(reduced_geometries)
        else:
            reduced, reduced_geometries = pin.buildReducedModel(base, ids, q_base), []
    except ValueError as error:
        shared = _shared_frame_names(base)
        if not shared:
            raise
        raise URDFError(f"{robot_name}: joints cannot be locked where a joint and a link "
                        f"share a name ({name_list(shared)}): Pinocchio's buildReducedModel "
                        f"finds frames by name ({error}); rename one of each pair in the "
                        "URDF") from error
    unmimicked = reduced if mimics else None
    if mimics:
        reduced, mimics = apply_mimics(reduced, mimics, URDFError)
    visual = reduced_geometries.pop(0) if visual_model is not None else None
    collision = reduced_geometries.pop(0) if collision_model is not None else None
    q0 = np.concatenate([np.zeros(0)] + [
        q0[model.idx_qs[model.getJointId(reduced.names[j])]:][
            :reduced.joints[j].nq] for j in range(1, reduced.njoints)])
    return Reduction(reduced, visual, collision, unmimicked, list(mimics), q0)


def _shared_frame_names(model: pin.Model) -> list[str]:
    """The frame names ``model`` gives more than one frame (a URDF's joint named as a link:
    their names are apart there)."""
    seen: set[str] = set()
    shared = []
    for frame in model.frames:
        if frame.name in seen and frame.name not in shared:
            shared.append(frame.name)
        seen.add(frame.name)
    return shared


def unmimicked_lock(model: pin.Model, base: pin.Model, mimics: Sequence[MimicJoint],
                     names: Sequence[str], q: np.ndarray
                     ) -> tuple[np.ndarray, list[int], list[MimicJoint]]:
    """Locking ``names`` on a robot with mimic joints: Pinocchio reduces ``base``, the model
    without mimic joints, so the lock is made there (a joint that follows a locked one is
    locked with it) and the other relations are tied again afterwards. Returns ``q`` on
    ``base``, the ids of the joints to lock in it, and the relations that remain."""
    locked = set(names)
    for m in mimics:  # (each relation is on an independent joint: one pass)
        if m.mimicked in locked:
            locked.add(m.joint)
    values = joint_values(model, mimics, q)
    q_base = pin.neutral(base)
    for j in range(1, base.njoints):
        joint, own = base.joints[j], model.joints[j]
        if own.nq:
            q_base[joint.idx_q:joint.idx_q + joint.nq] = q[own.idx_q:own.idx_q + own.nq]
        elif base.names[j] in values:  # (a mimic joint: its value, (cos, sin) if continuous)
            value = values[base.names[j]]
            q_base[joint.idx_q:joint.idx_q + joint.nq] = (
                (np.cos(value), np.sin(value)) if joint.nq == 2 else value)
    ids = [base.getJointId(name) for name in sorted(locked, key=base.getJointId)]
    return q_base, ids, [m for m in mimics if m.joint not in locked and m.mimicked not in locked]
