"""The frames of a Pinocchio model: one looked up by name or id (:func:`find_frame`, what
``Robot.frame_id`` does), all of them listed (:func:`list_frames`), and the default end effector
of a robot that names none (:func:`chain_tip`, :func:`only_leaf_body`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .exceptions import FrameNotFound
from .validation import name_list

#: Which frame a name shared by several frames means, most preferred first: an operational
#: frame or a link (body) over a sensor, a fixed joint and a moving joint of the same name.
FRAME_PREFERENCE: tuple[pin.FrameType, ...] = (
    pin.FrameType.OP_FRAME, pin.FrameType.BODY, pin.FrameType.SENSOR,
    pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT)


class FrameInfo(NamedTuple):
    """One frame of a robot, as :meth:`Robot.frames` lists it."""

    #: index in ``model.frames`` (what :meth:`Robot.frame_id` returns)
    id: int
    #: the frame's name (a link's, a joint's, an operational frame's)
    name: str
    #: Pinocchio's frame type: ``"BODY"`` (a link), ``"JOINT"``, ``"FIXED_JOINT"``,
    #: ``"OP_FRAME"`` or ``"SENSOR"``
    type: str
    #: the joint that moves it (``"universe"``: fixed to the world)
    parent_joint: str



def find_frame(model: pin.Model, name: str | int, frame_type: pin.FrameType | str | None,
               robot_name: str) -> int:
    """Index of frame ``name`` (a frame name, or an index of ``model.frames``) of the robot
    ``robot_name``, ``frame_type`` picking among frames of that name: see ``Robot.frame_id``."""
    frames = model.frames
    if isinstance(name, (int, np.integer)) and not isinstance(name, (bool, np.bool_)):
        if not 0 <= int(name) < len(frames):
            raise FrameNotFound(str(name), [f.name for f in frames], robot_name,
                                f"frame id {int(name)} is outside 0..{len(frames) - 1}")
        return int(name)
    if not isinstance(name, str):
        raise TypeError(f"frame must be a frame name (str) or a frame id (int), got {name!r}")
    wanted = None if frame_type is None else frame_type_of(frame_type)
    matches = [i for i, f in enumerate(frames) if f.name == name]
    if wanted is not None:
        kinds = [str(frames[i].type).rsplit(".", 1)[-1] for i in matches]
        matches = [i for i in matches if frames[i].type == wanted]
        if not matches and kinds:
            raise FrameNotFound(name, [f.name for f in frames], robot_name,
                                f"frame {name!r} of type {type_name(wanted)} not found in "
                                f"{robot_name}; frames of that name have types {kinds}")
    if not matches:
        raise FrameNotFound(name, [f.name for f in frames], robot_name)
    return min(matches, key=lambda i: FRAME_PREFERENCE.index(frames[i].type))


def list_frames(model: pin.Model, pattern: str | None = None) -> list[FrameInfo]:
    """Every frame of ``model`` whose name contains ``pattern``, ignoring case (every frame
    without it): see ``Robot.frames``."""
    if pattern is not None and not isinstance(pattern, str):
        raise TypeError(f"pattern must be a str (part of a frame name), got {pattern!r}")
    wanted = None if pattern is None else pattern.lower()
    return [FrameInfo(i, f.name, type_name(f.type), model.names[f.parentJoint])
            for i, f in enumerate(model.frames)
            if wanted is None or wanted in f.name.lower()]


def chain_tip(model: pin.Model, locked: Sequence[str] = ()) -> str:
    """The name of the frame at the tip of ``model``'s longest kinematic chain (most moving
    joints from the root, ``locked`` joints not counted): the deepest link (or operational
    frame) carried by the last joint of that chain; the default end effector of a robot
    that names none. Ties go to the chain reaching farthest from its root, then to the first
    in the model."""
    if model.njoints <= 1:
        return model.frames[len(model.frames) - 1].name
    locked_ids = {model.getJointId(n) for n in locked if model.existJointName(n)}
    depth = np.zeros(model.njoints, dtype=int)
    reach = np.zeros(model.njoints)
    for j in range(1, model.njoints):
        moving = model.joints[j].nv > 0 and j not in locked_ids
        depth[j] = depth[model.parents[j]] + int(moving)
        reach[j] = reach[model.parents[j]] + float(
            np.linalg.norm(model.jointPlacements[j].translation))
    frame_depth = np.zeros(len(model.frames), dtype=int)
    for i, f in enumerate(model.frames):
        if i:
            frame_depth[i] = frame_depth[f.parentFrame] + 1 if f.parentFrame < i else 1

    def key(i: int) -> tuple:
        f = model.frames[i]
        j = f.parentJoint
        if j in locked_ids:  # a locked joint's frames belong to the joint before it
            j = model.parents[j]
        kind = f.type in (pin.FrameType.BODY, pin.FrameType.OP_FRAME)
        return (int(depth[j]), kind, float(reach[j]) + float(np.linalg.norm(
            f.placement.translation)), int(frame_depth[i]), -i)

    return model.frames[max(range(1, len(model.frames)), key=key)].name


def only_leaf_body(model: pin.Model, source: str) -> str:
    """Name of the single leaf link of ``model`` (the default end effector of a URDF)."""
    bodies = [f for f in model.frames if f.type == pin.FrameType.BODY]
    # a link's children are the joint frames whose parent frame it is: a leaf has none
    children = {model.frames[f.parentFrame].name for f in model.frames if f.parentFrame}
    leaves = [f.name for f in bodies if f.name not in children]
    if len(leaves) == 1:
        return leaves[0]
    raise ValueError(f"{source} has several leaf links {name_list(leaves)}; pass "
                     "ee_frame= (Robot.frames() lists every frame)")


def frame_type_of(value) -> pin.FrameType:
    """``value`` (a ``pin.FrameType`` or its name) as a ``pin.FrameType``."""
    if isinstance(value, pin.FrameType):
        return value
    if isinstance(value, str) and value.upper() in pin.FrameType.names:
        return pin.FrameType.names[value.upper()]
    raise ValueError(f"frame_type must be a pinocchio.FrameType or one of "
                     f"{sorted(pin.FrameType.names)}, got {value!r}")


def type_name(kind: pin.FrameType) -> str:
    return str(kind).rsplit(".", 1)[-1]
