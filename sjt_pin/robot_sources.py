"""Where a :class:`~sjt_pin.robot.Robot`'s model comes from, beyond Pinocchio's parser:
example-robot-data's robots (:func:`example_robot`: the name checked, the mimic relations of
the URDF file applied, the default end effector and locked grippers, the capsules of the
collision model fixed, the mesh package's folder) and a URDF's mesh folders and visual
geometry (:func:`mesh_dirs`, :func:`visual_model`)."""

from __future__ import annotations

import difflib
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from . import mesh_paths
from .exceptions import URDFError
from .mimic import MimicJoint, apply_mimics, reduced_configuration
from .robot_frames import chain_tip
from .urdf_check import URDFSource, read_urdf, urdf_mimics
from .validation import names_arg

#: End-effector frames used when ``Robot.from_example`` is called without ``ee_frame``.
DEFAULT_EE_FRAMES: dict[str, str] = {
    "panda": "panda_hand",
    "panda_collision": "panda_hand",
    "ur3": "tool0",
    "ur3_limited": "tool0",
    "ur5": "tool0",
    "ur5_limited": "tool0",
    "ur10": "tool0",
    "ur10_limited": "tool0",
    "talos": "gripper_left_joint",
    "talos_full": "gripper_left_joint",
    "talos_arm": "gripper_left_joint",
    "kinova": "j2s6s200_end_effector",
    "z1": "gripperStator",  # the rigid half of the gripper (a link; a fixed joint shares it)
    "xarm7": "link_eef",
}

#: Gripper joints that ``Robot.from_example`` locks (removes from the model, at the reference
#: configuration) unless ``locked_joints=`` says otherwise: on these robots the default end
#: effector lies beyond the gripper joint, which would otherwise be an IK degree of freedom.
#: The Panda keeps its fingers: they lie beyond ``panda_hand``, so no task on the hand moves
#: them (``locked_joints=["panda_finger_joint1", "panda_finger_joint2"]`` removes them).
DEFAULT_LOCKED_JOINTS: dict[str, tuple[str, ...]] = {
    "z1": ("jointGripper",),
    "talos_arm": ("gripper_left_joint",),
    "talos": ("gripper_left_joint", "gripper_right_joint"),
    "talos_full": tuple(f"gripper_{side}_{part}" for side in ("left", "right") for part in (
        "joint", "inner_double_joint", "fingertip_1_joint", "fingertip_2_joint",
        "inner_single_joint", "fingertip_3_joint", "motor_single_joint")),
}


class ExampleRobot(NamedTuple):
    """An example-robot-data robot's parts, as ``Robot.from_example`` builds it from them."""

    model: pin.Model  #: with its mimic joints (the relations of its URDF file)
    ee_frame: str | int
    q0: np.ndarray  #: its SRDF's reference configuration
    visual_model: pin.GeometryModel | None
    collision_model: pin.GeometryModel | None
    urdf: str | None  #: its URDF file
    package_dirs: list[str]
    mimics: list[MimicJoint]
    unmimicked: pin.Model | None  #: the model without its mimic joints (None without any)
    locked: list[str]  #: the joints to lock


def example_robot(name: str, ee_frame: str | int | None,
                  locked_joints: Sequence[str] | None) -> ExampleRobot:
    """The parts of example-robot-data's robot ``name`` (see ``Robot.from_example``): a
    ``ValueError`` naming close names for a name it does not know; a warning when the end
    effector is guessed (:func:`~sjt_pin.robot_frames.chain_tip`)."""
    import example_robot_data as erd
    from example_robot_data.robots_loader import ROBOTS

    if not isinstance(name, str):
        raise TypeError(f"name must be a str naming an example-robot-data robot, got "
                        f"{type(name).__name__}")
    if name not in ROBOTS:
        by_lower = {known.lower(): known for known in ROBOTS}
        close = [by_lower[m] for m in difflib.get_close_matches(name.lower(), by_lower, n=3)]
        hint = f"did you mean {' or '.join(map(repr, close))}? " if close else ""
        raise ValueError(f"name {name!r} is not an example-robot-data robot; {hint}"
                         f"known: {sorted(ROBOTS)}")
    wrapper = load_example(erd, name)
    urdf = getattr(wrapper, "urdf", None)
    model, q0, mimics = with_mimics(wrapper.model, wrapper.q0, urdf)
    locked = [j for j in DEFAULT_LOCKED_JOINTS.get(name, ()) if model.existJointName(j)] \
        if locked_joints is None else list(names_arg(locked_joints, "locked_joints"))
    guessed = ee_frame is None and name not in DEFAULT_EE_FRAMES
    if ee_frame is None:
        ee_frame = DEFAULT_EE_FRAMES.get(name) or chain_tip(model, locked)
    if guessed:
        warnings.warn(
            f"{name}: no end effector given and none known for it; ee_frame={ee_frame!r}, "
            f"the tip of its longest kinematic chain. Pass ee_frame= to choose another "
            f"(robot.frames('hand') lists the frames whose name holds 'hand')",
            UserWarning, stacklevel=3)
    collision = capsules_as_long_as_their_cylinders(wrapper.collision_model,
                                                     wrapper.model, urdf)
    return ExampleRobot(model, ee_frame, q0, wrapper.visual_model, collision, urdf,
                        example_dirs(urdf), mimics, wrapper.model if mimics else None, locked)


def mesh_dirs(source: URDFSource, package_dirs, allow_outside: bool, must_exist: bool
               ) -> list[str]:
    """The folders meshes are read from (see :meth:`Robot.from_urdf`): ``package_dirs``, the
    package roots found above a URDF file, its own folder; every mesh reference is checked
    against them."""
    if isinstance(package_dirs, (str, Path)):
        package_dirs = [package_dirs]  # one folder, not a sequence of characters
    dirs = [str(p) for p in (package_dirs or [])]
    for folder in dirs:
        if not os.path.isdir(folder):
            raise URDFError(f"package_dirs: {folder!r} is not a folder")
    urdf_dir = None
    if source.path is not None:
        urdf_dir = source.path.resolve().parent
        references = mesh_paths.mesh_references(source.data)
        dirs += mesh_paths.guess_package_dirs(source.path, references, dirs)
        dirs.append(str(urdf_dir))
    mesh_paths.check_references(source.label, source.data, urdf_dir, dirs, allow_outside,
                                must_exist=must_exist)
    return dirs


# example-robot-data's loaders by name where its registry gives another robot's: 5.0 registers
# "ur3" to UR5Loader (ur5_robot.urdf), so that a UR3 asked for came as a UR5 named "ur3"
OWN_LOADERS = {"ur3": "UR3Loader"}


def load_example(erd, name: str):
    """example-robot-data's robot ``name`` (by its own loader where the registry names
    another's, :data:`OWN_LOADERS`); a clear error for an SDF model (Cassie) where this
    Pinocchio has no SDF parser (``pinocchio.WITH_SDFORMAT``)."""
    from example_robot_data import robots_loader

    own = getattr(robots_loader, OWN_LOADERS.get(name, ""), None)
    try:
        return own().robot if own is not None else erd.load(name)
    except ImportError as exc:
        if "SDF" in str(exc) and not getattr(pin, "WITH_SDFORMAT", False):
            raise URDFError(
                f"{name} is an SDF model, and this Pinocchio was built without an SDF parser "
                f"(pinocchio.WITH_SDFORMAT is False; the PyPI wheels are): a Pinocchio built "
                "with sdformat loads it") from exc
        raise


def with_mimics(model: pin.Model, q0: np.ndarray, urdf: str | None
                 ) -> tuple[pin.Model, np.ndarray, list[MimicJoint]]:
    """An example-robot-data model (parsed without mimic joints) with the mimic relations of
    its URDF file applied, and its reference configuration without the mimic coordinates."""
    if not urdf or not Path(urdf).is_file():
        return model, q0, []
    source = read_urdf(Path(urdf))
    reduced, mimics = apply_mimics(model, urdf_mimics(source), source.error)
    if not mimics:
        return model, q0, []
    return reduced, reduced_configuration(model, reduced, np.asarray(q0, dtype=float)), mimics


def visual_model(model: pin.Model, source: URDFSource, dirs: list[str]) -> pin.GeometryModel:
    """The visual geometry of ``source``; :class:`URDFError` if its meshes cannot be found."""
    try:
        if source.path is None:
            return pin.buildGeomFromUrdfString(model, source.text, pin.VISUAL, package_dirs=dirs)
        return pin.buildGeomFromUrdf(model, str(source.path), pin.VISUAL, package_dirs=dirs)
    except (ValueError, RuntimeError) as exc:
        raise URDFError(
            f"cannot load the visual meshes of {source.label} (package_dirs={dirs}): {exc}; "
            "pass package_dirs= or load_visuals=False"
        ) from exc


def capsules_as_long_as_their_cylinders(geometry: pin.GeometryModel | None, model: pin.Model,
                                        urdf: str | None) -> pin.GeometryModel | None:
    """An example-robot-data collision model whose loader turned the URDF's cylinders (with a
    sphere of their radius at each end) into capsules (``panda_collision``), each capsule as
    long as its cylinder: the loader passes the cylinder's half length where
    ``coal.Capsule(radius, lz)`` takes the whole, so its capsules were half as long and a
    limit on them let the URDF's geometry come 4 mm inside its margin. A capsule matches the
    URDF cylinder on the same joint, at the same placement, of the same radius; the model is
    returned as it is where none is found (or once the loader passes the whole length)."""
    if geometry is None or urdf is None:
        return geometry
    import coal

    if not any(isinstance(g.geometry, coal.Capsule) for g in geometry.geometryObjects):
        return geometry
    source = pin.buildGeomFromUrdf(model, urdf, pin.COLLISION, package_dirs=example_dirs(urdf))
    cylinders = [g for g in source.geometryObjects if isinstance(g.geometry, coal.Cylinder)]
    fixed = geometry.copy()
    for capsule in fixed.geometryObjects:
        shape = capsule.geometry
        if not isinstance(shape, coal.Capsule):
            continue
        for cylinder in cylinders:
            if (cylinder.parentJoint == capsule.parentJoint
                    and cylinder.placement.isApprox(capsule.placement, 1e-12)
                    and cylinder.geometry.radius == shape.radius
                    and cylinder.geometry.halfLength != shape.halfLength):
                capsule.geometry = coal.Capsule(shape.radius, 2.0 * cylinder.geometry.halfLength)
                break
    return fixed


def example_dirs(urdf: str | None) -> list[str]:
    """The folder that contains ``example-robot-data`` (its meshes' package), for an
    example-robot-data URDF file."""
    if urdf is None or urdf.lstrip().startswith("<"):
        return []
    for folder in Path(urdf).resolve().parents:
        if folder.name == "example-robot-data":
            return [str(folder.parent)]
    return []
