"""Robot: a Pinocchio model of a URDF robot with a chosen end-effector frame.

Kinematic quantities follow Pinocchio's conventions: ``fk`` returns the world pose of a frame
(``oMf``), ``jacobian`` its 6 x nv frame Jacobian [linear; angular] in the frame's own (LOCAL) axes.
"""

from __future__ import annotations

import difflib
import importlib.resources
import math
import os
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from . import mesh_paths
from .exceptions import FrameNotFound, URDFError
from .joint_ranges import position_ranges
from .mimic import MimicJoint, apply_mimics, joint_values, reduced_configuration
from .urdf_check import URDFSource, check_urdf, load_model, read_urdf, urdf_mimics
from .validation import UnitBlocks, configuration, name_list

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

#: Which frame a name shared by several frames means, most preferred first: an operational
#: frame or a link (body) over a sensor, a fixed joint and a moving joint of the same name.
FRAME_PREFERENCE: tuple[pin.FrameType, ...] = (
    pin.FrameType.OP_FRAME, pin.FrameType.BODY, pin.FrameType.SENSOR,
    pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT)

#: Bytes one ``pin.Data`` may take by default (:meth:`Robot.data_bytes`); a robot whose data
#: would need more is refused (pass ``memory_budget=``), one needing a quarter of it warned.
#: Each thread that queries a robot, and each solver, holds its own ``pin.Data``.
MEMORY_BUDGET = 2e9

#: A target farther from the robot's base than this many times its reach gets a warning.
REACH_FACTOR = 10.0


class FrameInfo(NamedTuple):
    """One frame of a robot, as :meth:`Robot.frames` lists it."""

    id: int  #: index in ``model.frames``
    name: str
    type: str  #: Pinocchio's frame type: ``"BODY"`` (a link), ``"JOINT"``, ``"FIXED_JOINT"``,
    #: ``"OP_FRAME"`` or ``"SENSOR"``
    parent_joint: str  #: the joint that moves it (``"universe"``: fixed to the world)


#: guards Pinocchio's global random generator (seeded and drawn by random_configuration)
_PINOCCHIO_RNG = threading.Lock()


class Robot:
    """A kinematic model (``pin.Model``) with one end-effector frame.

    Build one with :meth:`from_example`, :meth:`from_urdf` or :meth:`planar3`. ``model``, ``data``,
    ``visual_model`` and ``collision_model`` are Pinocchio's own objects; ``data`` is this robot's
    scratch space, overwritten by every kinematic call.

    ``ee_frame`` is a frame name or id, ``frame_type`` picks among frames sharing the name (see
    :meth:`frame_id`). Geometry handed in is checked against the folders its meshes may come
    from (``package_dirs`` and the folder of the ``urdf`` file, :mod:`sjt_pin.mesh_paths`)
    unless ``allow_outside_meshes``; with neither named, it is the caller's own and not checked.
    A model whose ``pin.Data`` would take more than ``memory_budget`` bytes is refused
    (:data:`MEMORY_BUDGET`).
    """

    def __init__(
        self,
        model: pin.Model,
        ee_frame: str | int,
        *,
        q0: np.ndarray | None = None,
        name: str | None = None,
        visual_model: pin.GeometryModel | None = None,
        collision_model: pin.GeometryModel | None = None,
        urdf: str | None = None,
        package_dirs: Sequence[str] = (),
        frame_type: pin.FrameType | str | None = None,
        allow_outside_meshes: bool = False,
        memory_budget: float = MEMORY_BUDGET,
        mimic_joints: Sequence[MimicJoint] = (),
    ):
        self.model = model
        #: the mimic relations of ``model``'s mimic joints (see :mod:`sjt_pin.mimic`)
        self.mimic_joints: list[MimicJoint] = list(mimic_joints)
        #: ``model`` before its mimic joints were made (what a pickled robot carries)
        self._unmimicked: pin.Model | None = None
        self._local = threading.local()  # one pin.Data per thread: queries never race
        self.name = name or model.name
        _check_memory(model, self.name, memory_budget)
        self.visual_model = visual_model
        self.collision_model = collision_model
        self.urdf = urdf  #: the URDF file path or XML text the model came from
        self.package_dirs = list(package_dirs)
        #: the folders mesh files may be read from (None: anywhere, ``allow_outside_meshes``)
        self.mesh_roots: tuple[Path, ...] | None = None
        if not allow_outside_meshes:
            urdf_dir = (Path(urdf).resolve().parent if urdf is not None and
                        not urdf.lstrip().startswith("<") else None)
            # geometry the caller built, naming no URDF file or folder, is theirs: None
            self.mesh_roots = mesh_paths.roots(urdf_dir, self.package_dirs) or None
            if self.mesh_roots is not None:
                for geometry in (visual_model, collision_model):
                    mesh_paths.check_geometry(geometry, self.mesh_roots, self.name)
        self.ee_frame_id = self.frame_id(ee_frame, frame_type)
        self.ee_frame = model.frames[self.ee_frame_id].name
        self._units = _unit_blocks(model)
        #: an upper bound of the distance from the base any frame can reach, m
        self.reach, self._base_q = _reach(model)
        self._lower, self._upper = position_ranges(model)
        limit = np.asarray(model.velocityLimit, dtype=float)
        self._velocity = np.where((limit > 0) & (limit < 1e30), limit, np.inf)
        #: name of the joint of each velocity (tangent) index: columns of J, entries of dq
        self.velocity_names: list[str] = [
            model.names[j] for j in range(1, model.njoints) for _ in range(model.joints[j].nv)]
        self.locked_joints: list[str] = []  #: joints removed by :meth:`reduced`
        # without a reference configuration: the neutral one, clipped into the limits
        self.q0 = (np.clip(pin.neutral(model), self._lower, self._upper) if q0 is None
                   else self._inside(self.check_q(q0, "q0")))

    @property
    def data_bytes(self) -> int:
        """Estimated bytes of one ``pin.Data`` of this model (it grows as nv³: Pinocchio
        keeps nv x nv x nv second-order derivative tensors)."""
        return _data_bytes(self.model)

    def __getstate__(self) -> dict:
        """A pickled robot (``solve_many``'s workers) carries its kinematic model, not its
        meshes: ``visual_model`` and ``collision_model`` are ``None`` after unpickling."""
        state = self.__dict__.copy()
        del state["_local"]  # per-thread scratch space: each process makes its own
        state["visual_model"] = state["collision_model"] = None
        if len(self.model.mimicking_joints):
            # Pinocchio 4.1 unpickles a mimic joint broken (nvExtended -1: fk then crashes);
            # the model goes as the one without mimic joints, the relations applied anew
            if self._unmimicked is None:
                raise TypeError(f"robot {self.name!r} has Pinocchio mimic joints but no model "
                                "without them to pickle (load it with Robot.from_urdf or "
                                "Robot.from_example)")
            state["model"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        if state["model"] is None:
            state["model"], _ = apply_mimics(state["_unmimicked"], state["mimic_joints"],
                                             URDFError)
        self.__dict__.update(state)
        self._local = threading.local()

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def from_example(cls, name: str, ee_frame: str | int | None = None, *,
                     frame_type: pin.FrameType | str | None = None,
                     locked_joints: Sequence[str] | None = None) -> Robot:
        """Load ``name`` from example-robot-data (``"panda"``, ``"ur5"``, ``"talos_full"``, ...;
        ``example_robot_data.robots_loader.ROBOTS`` lists every name).

        ``ee_frame`` (a frame name, or an id of the model as loaded, before joints are locked;
        ``frame_type`` picks among frames sharing the name, see :meth:`frame_id`) defaults to
        :data:`DEFAULT_EE_FRAMES` for the robots listed there.
        ``locked_joints`` (joint names) are removed from the model at the reference
        configuration (see :meth:`reduced`); by default the gripper joints of
        :data:`DEFAULT_LOCKED_JOINTS`, ``()`` for none. ``q0`` is the robot's reference
        configuration from its SRDF. Mimic joints (Panda's second finger, TALOS's
        grippers) are Pinocchio mimic joints, as in :meth:`from_urdf`.
        """
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
        wrapper = _load_example(erd, name)
        urdf = getattr(wrapper, "urdf", None)
        model, q0, mimics = _with_mimics(wrapper.model, wrapper.q0, urdf)
        locked = [j for j in DEFAULT_LOCKED_JOINTS.get(name, ()) if model.existJointName(j)] \
            if locked_joints is None else list(_names_arg(locked_joints, "locked_joints"))
        guessed = ee_frame is None and name not in DEFAULT_EE_FRAMES
        if ee_frame is None:
            ee_frame = DEFAULT_EE_FRAMES.get(name) or chain_tip(model, locked)
        if guessed:
            warnings.warn(
                f"{name}: no end effector given and none known for it; ee_frame={ee_frame!r}, "
                f"the tip of its longest kinematic chain. Pass ee_frame= to choose another "
                f"(robot.frames('hand') lists the frames whose name holds 'hand')",
                UserWarning, stacklevel=2)
        # the full model's frame named by ee_frame, found again (by name) in the reduced one
        collision = _capsules_as_long_as_their_cylinders(wrapper.collision_model,
                                                         wrapper.model, urdf)
        full = cls(model, ee_frame, q0=q0, name=name, frame_type=frame_type,
                   visual_model=wrapper.visual_model, collision_model=collision,
                   urdf=urdf, package_dirs=_example_dirs(urdf), mimic_joints=mimics)
        full._unmimicked = wrapper.model if mimics else None
        robot = full.reduced(locked) if locked else full
        robot._warn_q0_on_limits()
        return robot

    @classmethod
    def from_urdf(
        cls,
        path_or_xml: str | Path | bytes,
        ee_frame: str | int | None = None,
        package_dirs: Sequence[str | Path] | str | Path | None = None,
        *,
        load_visuals: bool = True,
        frame_type: pin.FrameType | str | None = None,
        locked_joints: Sequence[str] = (),
        allow_outside_meshes: bool = False,
        memory_budget: float = MEMORY_BUDGET,
    ) -> Robot:
        """Load a URDF from a file path (``str`` or ``pathlib.Path``) or from XML text (a string,
        or UTF-8 bytes, starting with ``<``).

        ``ee_frame`` (a frame name or id, ``frame_type`` as in :meth:`frame_id`) defaults to the
        URDF's only leaf link; with several leaves it must be given. ``locked_joints`` are
        removed at the neutral configuration (:meth:`reduced`).

        Meshes: ``package_dirs`` (folders, or one folder) are searched for ``package://`` and
        relative mesh paths, then the URDF's own folder. A ``package://pkg/...`` that none of
        them holds is looked for above the URDF file: the folder that contains a folder named
        ``pkg`` holding the URDF is added (so example-robot-data's and ROS packages' own files
        find their meshes). With ``load_visuals=True`` (default) the visual meshes are loaded,
        and a mesh that cannot be found raises :class:`URDFError` naming it and the folder to
        pass; ``load_visuals=False`` loads no geometry (``visual_model`` is None; the viewer
        then has nothing to draw). Mesh files are read only from those folders, after resolving
        ``..`` and symbolic links: a mesh path outside them (``../``, an absolute path,
        ``file://``, a link pointing out) raises :class:`URDFError` naming the path, unless
        ``allow_outside_meshes=True``.

        The URDF is checked before Pinocchio parses it (:mod:`sjt_pin.urdf_check`): a broken
        one raises :class:`URDFError` naming the file and the joint or link at fault. A model
        whose ``pin.Data`` would take more than ``memory_budget`` bytes is refused
        (:data:`MEMORY_BUDGET`). A joint with ``<mimic>`` becomes a Pinocchio mimic joint
        without a coordinate of its own (:mod:`sjt_pin.mimic`); ``lower == upper`` locks a joint
        at that value (:mod:`sjt_pin.joint_ranges`); a planar joint moves in the plane normal to
        its ``<axis>`` (:mod:`sjt_pin.planar`).
        """
        source = read_urdf(path_or_xml)
        content = check_urdf(source)
        dirs = _mesh_dirs(source, package_dirs, allow_outside_meshes, load_visuals)
        model, mimics, unmimicked = load_model(source, content)
        _check_memory(model, source.label, memory_budget)
        if ee_frame is None:
            ee_frame = _only_leaf_body(model, source.label)
        visual = _visual_model(model, source, dirs) if load_visuals else None
        urdf = source.text if source.path is None else str(source.path)
        robot = cls(model, ee_frame, visual_model=visual, urdf=urdf, package_dirs=dirs,
                    frame_type=frame_type, allow_outside_meshes=allow_outside_meshes,
                    memory_budget=memory_budget, mimic_joints=mimics)
        robot._unmimicked = unmimicked if mimics else None
        locked = list(_names_arg(locked_joints, "locked_joints"))
        return robot.reduced(locked) if locked else robot

    @classmethod
    def planar3(cls, ee_frame: str = "ee") -> Robot:
        """The paper's 3-link planar arm (Fig. 4): ``robots/planar3.urdf``, joints about +z."""
        urdf = importlib.resources.files("sjt_pin.robots").joinpath("planar3.urdf")
        with importlib.resources.as_file(urdf) as path:
            robot = cls.from_urdf(path, ee_frame=ee_frame)
        robot.name = "planar3"
        return robot

    # -- dimensions and limits -----------------------------------------------------------------
    @property
    def nq(self) -> int:
        """Size of a configuration vector."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Size of a velocity vector (= columns of the Jacobian)."""
        return self.model.nv

    @property
    def lower_limits(self) -> np.ndarray:
        """Lower position limits (nq,) in rad or m, those the solvers enforce: the URDF's for
        1-DoF revolute and prismatic joints, ``-inf`` elsewhere (no limit in the URDF,
        continuous joints, a floating base)."""
        return self._lower.copy()

    @property
    def upper_limits(self) -> np.ndarray:
        """Upper position limits (nq,) in rad or m; ``+inf`` where none (see ``lower_limits``)."""
        return self._upper.copy()

    @property
    def velocity_limits(self) -> np.ndarray:
        """Joint speed limits (nv,) in rad/s or m/s; ``+inf`` where the URDF gives none."""
        return self._velocity.copy()

    def _inside(self, q0: np.ndarray) -> np.ndarray:
        """``q0`` clipped into the position limits, with a warning naming the joints moved."""
        outside = (q0 < self._lower) | (q0 > self._upper)
        if not outside.any():
            return q0.copy()
        names = [self.model.names[j] for j in range(1, self.model.njoints)
                 if self.model.joints[j].nq == 1 and outside[self.model.joints[j].idx_q]]
        warnings.warn(f"{self.name}: the reference configuration q0 puts {names} outside their "
                      f"URDF limits; q0 is clipped into range", UserWarning, stacklevel=3)
        return np.clip(q0, self._lower, self._upper)

    # -- frames and kinematics ---------------------------------------------------------------
    def frame_id(self, name: str | int, frame_type: pin.FrameType | str | None = None) -> int:
        """Index of frame ``name`` (a frame name, or an index of ``model.frames``).

        Several frames may share a name (a link and the fixed joint that attaches it, say):
        ``frame_type`` (``pin.FrameType`` or its name, ``"BODY"``, ``"JOINT"``, ...) picks
        one; without it the first in :data:`FRAME_PREFERENCE` order is meant (an operational
        frame or link before a joint). :class:`FrameNotFound` (a ``KeyError`` listing close
        names and the robot's frames) if there is none.
        """
        frames = self.model.frames
        if isinstance(name, (int, np.integer)) and not isinstance(name, (bool, np.bool_)):
            if not 0 <= int(name) < len(frames):
                raise FrameNotFound(str(name), [f.name for f in frames], self.name,
                                    f"frame id {int(name)} is outside 0..{len(frames) - 1}")
            return int(name)
        if not isinstance(name, str):
            raise TypeError(f"frame must be a frame name (str) or a frame id (int), got {name!r}")
        wanted = None if frame_type is None else _frame_type(frame_type)
        matches = [i for i, f in enumerate(frames) if f.name == name]
        if wanted is not None:
            kinds = [str(frames[i].type).rsplit(".", 1)[-1] for i in matches]
            matches = [i for i in matches if frames[i].type == wanted]
            if not matches and kinds:
                raise FrameNotFound(name, [f.name for f in frames], self.name,
                                    f"frame {name!r} of type {_type_name(wanted)} not found in "
                                    f"{self.name}; frames of that name have types {kinds}")
        if not matches:
            raise FrameNotFound(name, [f.name for f in frames], self.name)
        return min(matches, key=lambda i: FRAME_PREFERENCE.index(frames[i].type))

    def frames(self, pattern: str | None = None) -> list[FrameInfo]:
        """Every frame of the model: id, name, type (``"BODY"`` for a link, ``"JOINT"``,
        ``"FIXED_JOINT"``, ``"OP_FRAME"``, ``"SENSOR"``) and the joint that moves it.

        ``pattern`` keeps the frames whose name contains it, ignoring case
        (``robot.frames("hand")``: the candidates for a hand's end effector).
        """
        if pattern is not None and not isinstance(pattern, str):
            raise TypeError(f"pattern must be a str (part of a frame name), got {pattern!r}")
        model = self.model
        wanted = None if pattern is None else pattern.lower()
        return [FrameInfo(i, f.name, _type_name(f.type), model.names[f.parentJoint])
                for i, f in enumerate(model.frames)
                if wanted is None or wanted in f.name.lower()]

    def _warn_q0_on_limits(self) -> None:
        """Warn when the reference configuration puts a joint that moves the end effector
        exactly on a limit of its range (TIAGo's torso lift and first arm joint): a task that
        needs it to move further that way cannot, and a ``PostureTask`` pulls it there."""
        model = self.model
        chain = model.supports[model.frames[self.ee_frame_id].parentJoint]
        at = []
        for j in chain[1:]:
            joint = model.joints[j]
            if joint.nq != 1:
                continue
            i = joint.idx_q
            lower, upper = self._lower[i], self._upper[i]
            if not lower < upper:
                continue
            if abs(self.q0[i] - lower) <= 1e-9 * max(1.0, abs(lower)):
                at.append(f"{model.names[j]} (lower)")
            elif abs(self.q0[i] - upper) <= 1e-9 * max(1.0, abs(upper)):
                at.append(f"{model.names[j]} (upper)")
        if at:
            warnings.warn(
                f"{self.name}: the reference configuration q0 puts {name_list(at)} at a limit "
                f"of their URDF range, on the chain to {self.ee_frame!r}: they can move only "
                "away from it, and a PostureTask pulls them back onto it",
                UserWarning, stacklevel=3)

    def reduced(self, locked_joints: Sequence[str], q=None) -> Robot:
        """A copy without ``locked_joints`` (joint names): each is fixed at its value in ``q``
        (default: the reference configuration ``q0``), with Pinocchio's
        ``buildReducedModel``; visual and collision geometry follow. A locked joint is no
        degree of freedom of any task, limit or solver (a gripper, a joint a tool blocks). The
        end-effector frame keeps its name (a locked joint's frame becomes a fixed joint's);
        ``q0`` keeps the other joints' values.
        """
        names = list(_names_arg(locked_joints, "locked_joints"))
        model = self.model
        ids = []
        for joint in names:
            if not model.existJointName(joint) or joint == "universe":
                known = [model.names[j] for j in range(1, model.njoints)]
                close = difflib.get_close_matches(joint, known, n=3)
                hint = f"close names: {close}" if close else f"joints: {name_list(known)}"
                raise ValueError(f"locked_joints: {self.name} has no joint {joint!r}; {hint}")
            ids.append(model.getJointId(joint))
        q_ref = self.q0 if q is None else self.check_q(q)
        base, q_base, mimics = model, q_ref, self.mimic_joints
        if mimics:
            if self._unmimicked is None:
                raise TypeError(f"robot {self.name!r} has mimic joints but no model without "
                                "them to reduce (load it with from_urdf or from_example)")
            base = self._unmimicked
            q_base, ids, mimics = _unmimicked_lock(model, base, mimics, names, q_ref)
        geometries = [g for g in (self.visual_model, self.collision_model) if g is not None]
        if geometries:
            reduced, reduced_geometries = pin.buildReducedModel(base, geometries, ids, q_base)
            reduced_geometries = list(reduced_geometries)
        else:
            reduced, reduced_geometries = pin.buildReducedModel(base, ids, q_base), []
        unmimicked = reduced if mimics else None
        if mimics:
            reduced, mimics = apply_mimics(reduced, mimics, URDFError)
        visual = reduced_geometries.pop(0) if self.visual_model is not None else None
        collision = reduced_geometries.pop(0) if self.collision_model is not None else None
        q0 = np.concatenate([np.zeros(0)] + [
            self.q0[model.idx_qs[model.getJointId(reduced.names[j])]:][
                :reduced.joints[j].nq] for j in range(1, reduced.njoints)])
        robot = type(self).__new__(type(self))
        robot.__dict__.update(self.__dict__)
        robot._local = threading.local()
        robot.package_dirs = list(self.package_dirs)
        robot.model, robot.visual_model, robot.collision_model = reduced, visual, collision
        kind = model.frames[self.ee_frame_id].type  # the same frame: same name, same type
        same = [i for i, f in enumerate(reduced.frames) if f.name == self.ee_frame
                and f.type == kind]
        robot.ee_frame_id = same[0] if same else robot.frame_id(self.ee_frame)
        robot._units = _unit_blocks(reduced)
        robot.reach, robot._base_q = _reach(reduced)
        robot._lower, robot._upper = position_ranges(reduced)
        limit = np.asarray(reduced.velocityLimit, dtype=float)
        robot._velocity = np.where((limit > 0) & (limit < 1e30), limit, np.inf)
        robot.velocity_names = [reduced.names[j] for j in range(1, reduced.njoints)
                                for _ in range(reduced.joints[j].nv)]
        robot.q0 = q0
        robot.mimic_joints, robot._unmimicked = list(mimics), unmimicked
        robot.locked_joints = [*self.locked_joints, *names]
        return robot

    def check_q(self, q, name: str = "q") -> np.ndarray:
        """``q`` as a finite real vector of shape (nq,), on its manifold: each unit quaternion
        (free flyer, spherical joint) and each (cos, sin) pair (continuous, planar joint) of
        norm within :data:`~sjt_pin.validation.UNIT_TOL` of 1 (then normalised); otherwise
        ``ValueError`` naming ``name`` (and the joint)."""
        return self._units.check(configuration(q, name, self.model.nq, self.model.nv), name)

    @property
    def unit_coordinates(self) -> bool:
        """Whether a configuration holds unit-norm blocks (quaternions, (cos, sin) pairs)."""
        return bool(self._units)

    @property
    def unit_blocks(self) -> np.ndarray:
        """``(first, size)`` of each unit-norm block of a configuration, (k, 2) int64: the
        quaternions of free flyers and spherical joints, the (cos, sin) pairs of continuous
        and planar joints; none (k = 0) when there are none."""
        return self._units.layout

    def check_reach(self, position, q=None, name: str = "target") -> None:
        """Warn when ``position`` (m, world) lies more than :data:`REACH_FACTOR` times the
        robot's reach (:attr:`reach`) from its base: most likely a target in mm, or cm. The
        base is the world origin, or a floating base's position in ``q`` (no check without
        ``q`` then). ``step()`` checks its first targets, ``solve()`` each target. Never for a
        robot whose reach is infinite (a planar or unlimited prismatic joint)."""
        origin: float | np.ndarray = 0.0
        if self._base_q is not None:
            if q is None:
                return
            origin = np.asarray(q, dtype=float)[self._base_q:self._base_q + 3]
        # math.hypot: no overflow (it scales), NaN and inf pass through, no numpy warning state
        distance = math.hypot(*(np.asarray(position, dtype=float) - origin).tolist())
        # NaN, inf or an overflowing distance: the task error cannot be finite, step() raises
        if np.isfinite(distance) and distance > REACH_FACTOR * self.reach:
            where = "the origin" if self._base_q is None else "the robot's base"
            warnings.warn(
                f"{name} is {distance:.4g} m from {where}, more than {REACH_FACTOR:g} times "
                f"{self.name}'s reach ({self.reach:.3g} m): positions are in m (check its "
                "units: mm or cm by mistake?)", UserWarning, stacklevel=3)

    @property
    def data(self) -> pin.Data:
        """Pinocchio's scratch space of the calling thread (``fk``/``jacobian`` use it)."""
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        return data

    def fk(self, q, frame: str | int | None = None) -> pin.SE3:
        """World pose of ``frame`` (a name or id, as :meth:`frame_id` takes it; default: the
        end effector) at configuration ``q``.

        Safe to call from several threads (each has its own ``pin.Data``).
        """
        q = self.check_q(q)
        fid = self.ee_frame_id if frame is None else self.frame_id(frame)
        data = self.data
        pin.forwardKinematics(self.model, data, q)
        return pin.updateFramePlacement(self.model, data, fid)

    def jacobian(self, q, frame: str | int | None = None,
                 reference: pin.ReferenceFrame = pin.LOCAL) -> np.ndarray:
        """Frame Jacobian (6, nv), rows [linear; angular], in ``reference`` axes (LOCAL default);
        always 2-D, also for a robot with one joint."""
        q = self.check_q(q)
        fid = self.ee_frame_id if frame is None else self.frame_id(frame)
        J = pin.computeFrameJacobian(self.model, self.data, q, fid, reference)
        return np.asarray(J, dtype=float).reshape(6, self.model.nv)

    def joint_values(self, q) -> dict[str, float]:
        """Every 1-DoF joint's position at ``q`` (rad or m) by name, the mimic joints' from
        their relations included: what the robot's joint controllers take."""
        return joint_values(self.model, self.mimic_joints, self.check_q(q))

    def random_configuration(self, rng: np.random.Generator | None = None) -> np.ndarray:
        """A configuration drawn uniformly within the position limits (``[-pi, pi]`` if none),
        reproducibly from ``rng`` (it reseeds Pinocchio's global generator, under a lock)."""
        rng = np.random.default_rng() if rng is None else rng
        lower = np.where(np.isfinite(self.lower_limits), self.lower_limits, -np.pi)
        upper = np.where(np.isfinite(self.upper_limits), self.upper_limits, np.pi)
        with _PINOCCHIO_RNG:  # Pinocchio draws from one global generator, seeded from rng
            pin.seed(int(rng.integers(2**31 - 1)))
            return pin.randomConfiguration(self.model, lower, upper)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, ee_frame={self.ee_frame!r}, nq={self.nq}, nv={self.nv})"



def _mesh_dirs(source: URDFSource, package_dirs, allow_outside: bool, must_exist: bool
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


def _unmimicked_lock(model: pin.Model, base: pin.Model, mimics: Sequence[MimicJoint],
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
        elif base.names[j] in values:
            q_base[joint.idx_q] = values[base.names[j]]
    ids = [base.getJointId(name) for name in sorted(locked, key=base.getJointId)]
    return q_base, ids, [m for m in mimics if m.joint not in locked and m.mimicked not in locked]

def _load_example(erd, name: str):
    """example-robot-data's robot ``name``; a clear error for an SDF model (Cassie) where
    this Pinocchio has no SDF parser (``pinocchio.WITH_SDFORMAT``)."""
    try:
        return erd.load(name)
    except ImportError as exc:
        if "SDF" in str(exc) and not getattr(pin, "WITH_SDFORMAT", False):
            raise URDFError(
                f"{name} is an SDF model, and this Pinocchio was built without an SDF parser "
                f"(pinocchio.WITH_SDFORMAT is False; the PyPI wheels are): a Pinocchio built "
                "with sdformat loads it") from exc
        raise


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


def _with_mimics(model: pin.Model, q0: np.ndarray, urdf: str | None
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


def _visual_model(model: pin.Model, source: URDFSource, dirs: list[str]) -> pin.GeometryModel:
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


def _only_leaf_body(model: pin.Model, source: str) -> str:
    """Name of the single leaf link of ``model`` (the default end effector of a URDF)."""
    bodies = [f for f in model.frames if f.type == pin.FrameType.BODY]
    # a link's children are the joint frames whose parent frame it is: a leaf has none
    children = {model.frames[f.parentFrame].name for f in model.frames if f.parentFrame}
    leaves = [f.name for f in bodies if f.name not in children]
    if len(leaves) == 1:
        return leaves[0]
    raise ValueError(f"{source} has several leaf links {name_list(leaves)}; pass "
                     "ee_frame= (Robot.frames() lists every frame)")


def _frame_type(value) -> pin.FrameType:
    """``value`` (a ``pin.FrameType`` or its name) as a ``pin.FrameType``."""
    if isinstance(value, pin.FrameType):
        return value
    if isinstance(value, str) and value.upper() in pin.FrameType.names:
        return pin.FrameType.names[value.upper()]
    raise ValueError(f"frame_type must be a pinocchio.FrameType or one of "
                     f"{sorted(pin.FrameType.names)}, got {value!r}")


def _type_name(kind: pin.FrameType) -> str:
    return str(kind).rsplit(".", 1)[-1]


def _names_arg(value, name: str) -> tuple[str, ...]:
    """``value`` as a tuple of names (one str is one name)."""
    if isinstance(value, str):
        return (value,)
    try:
        names = tuple(value)
    except TypeError:
        raise TypeError(f"{name} must be joint names (a sequence of str), got {value!r}") from None
    if not all(isinstance(n, str) for n in names):
        raise TypeError(f"{name} must be joint names (a sequence of str), got {value!r}")
    return names


def _capsules_as_long_as_their_cylinders(geometry: pin.GeometryModel | None, model: pin.Model,
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
    source = pin.buildGeomFromUrdf(model, urdf, pin.COLLISION, package_dirs=_example_dirs(urdf))
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


def _example_dirs(urdf: str | None) -> list[str]:
    """The folder that contains ``example-robot-data`` (its meshes' package), for an
    example-robot-data URDF file."""
    if urdf is None or urdf.lstrip().startswith("<"):
        return []
    for folder in Path(urdf).resolve().parents:
        if folder.name == "example-robot-data":
            return [str(folder.parent)]
    return []


def _unit_blocks(model: pin.Model) -> UnitBlocks:
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


def _reach(model: pin.Model) -> tuple[float, int | None]:
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


def _data_bytes(model: pin.Model) -> int:
    """Estimated bytes of one ``pin.Data``: 30 nv³ + 1100 nv², fitted to Pinocchio 3 on
    serial chains (measured 41 MB at nv = 100, 279 MB at 200, 901 MB at 300)."""
    nv = model.nv
    return int(30 * nv**3 + 1100 * nv**2)


def _check_memory(model: pin.Model, label: str, budget: float) -> None:
    """Refuse a model whose ``pin.Data`` would take more than ``budget`` bytes; warn above a
    quarter of it."""
    need = _data_bytes(model)
    if need > budget:
        raise ValueError(f"{label}: a pin.Data of this model (nv = {model.nv}) would take about "
                         f"{need / 1e9:.3g} GB, above memory_budget = {budget / 1e9:.3g} GB; "
                         "every thread and solver holds one (pass memory_budget= to allow it)")
    if need > budget / 4:
        warnings.warn(f"{label}: a pin.Data of this model (nv = {model.nv}) takes about "
                      f"{need / 1e9:.3g} GB, and every thread and solver holds one",
                      UserWarning, stacklevel=4)
