"""Robot: a Pinocchio model of a URDF robot with a chosen end-effector frame.

Kinematic quantities follow Pinocchio's conventions: ``fk`` returns the world pose of a frame
(``oMf``), ``jacobian`` its 6 x nv frame Jacobian [linear; angular] in the frame's own (LOCAL) axes.
"""

from __future__ import annotations

import importlib.resources
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from . import mesh_paths, model_measures, robot_sources
from .exceptions import URDFError
from .joint_locking import locked_ids, reduce_model
from .joint_ranges import at_limits, clipped_q0, position_ranges, random_within
from .mimic import MimicJoint, apply_mimics, joint_values
from .model_measures import MEMORY_BUDGET, REACH_FACTOR  # noqa: F401 (the docstrings' names)
from .robot_frames import (  # noqa: F401 (FRAME_PREFERENCE, chain_tip: their old path)
    FRAME_PREFERENCE,
    FrameInfo,
    chain_tip,
    find_frame,
    list_frames,
    only_leaf_body,
)
from .robot_sources import DEFAULT_EE_FRAMES, DEFAULT_LOCKED_JOINTS  # noqa: F401 (old path)
from .urdf_check import check_urdf, load_model, read_urdf
from .validation import configuration, name_list, names_arg


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
        model_measures.check_memory(model, self.name, memory_budget)
        self.visual_model = visual_model
        self.collision_model = collision_model
        self.urdf = urdf  #: the URDF file path or XML text the model came from
        self.package_dirs = list(package_dirs)
        #: the folders mesh files may be read from (None: anywhere, ``allow_outside_meshes``)
        self.mesh_roots: tuple[Path, ...] | None = None if allow_outside_meshes else (
            mesh_paths.geometry_roots(urdf, self.package_dirs, (visual_model, collision_model),
                                      self.name))
        self.ee_frame_id = self.frame_id(ee_frame, frame_type)
        self.ee_frame = model.frames[self.ee_frame_id].name
        self._units = model_measures.unit_blocks(model)
        #: an upper bound of the distance from the base any frame can reach, m
        self.reach, self._base_q = model_measures.reach(model)
        self._lower, self._upper = position_ranges(model)
        self._velocity = model_measures.velocity_limits(model)
        #: name of the joint of each velocity (tangent) index: columns of J, entries of dq
        self.velocity_names: list[str] = model_measures.velocity_names(model)
        self.locked_joints: list[str] = []  #: joints removed by :meth:`reduced`
        # without a reference configuration: the neutral one, clipped into the limits
        self.q0 = (np.clip(pin.neutral(model), self._lower, self._upper) if q0 is None
                   else self._inside(self.check_q(q0, "q0")))

    @property
    def data_bytes(self) -> int:
        """Estimated bytes of one ``pin.Data`` of this model (it grows as nv³: Pinocchio
        keeps nv x nv x nv second-order derivative tensors)."""
        return model_measures.data_bytes(self.model)

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
        parts = robot_sources.example_robot(name, ee_frame, locked_joints)
        # the full model's frame named by ee_frame, found again (by name) in the reduced one
        full = cls(parts.model, parts.ee_frame, q0=parts.q0, name=name, frame_type=frame_type,
                   visual_model=parts.visual_model, collision_model=parts.collision_model,
                   urdf=parts.urdf, package_dirs=parts.package_dirs, mimic_joints=parts.mimics)
        full._unmimicked = parts.unmimicked
        robot = full.reduced(parts.locked) if parts.locked else full
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
        dirs = robot_sources.mesh_dirs(source, package_dirs, allow_outside_meshes, load_visuals)
        model, mimics, unmimicked = load_model(source, content)
        model_measures.check_memory(model, source.label, memory_budget)
        if ee_frame is None:
            ee_frame = only_leaf_body(model, source.label)
        visual = robot_sources.visual_model(model, source, dirs) if load_visuals else None
        urdf = source.text if source.path is None else str(source.path)
        robot = cls(model, ee_frame, visual_model=visual, urdf=urdf, package_dirs=dirs,
                    frame_type=frame_type, allow_outside_meshes=allow_outside_meshes,
                    memory_budget=memory_budget, mimic_joints=mimics)
        robot._unmimicked = unmimicked if mimics else None
        locked = list(names_arg(locked_joints, "locked_joints"))
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
        return clipped_q0(self.model, q0, self._lower, self._upper, self.name)

    # -- frames and kinematics ---------------------------------------------------------------
    def frame_id(self, name: str | int, frame_type: pin.FrameType | str | None = None) -> int:
        """Index of frame ``name`` (a frame name, or an index of ``model.frames``).

        Several frames may share a name (a link and the fixed joint that attaches it, say):
        ``frame_type`` (``pin.FrameType`` or its name, ``"BODY"``, ``"JOINT"``, ...) picks
        one; without it the first in :data:`FRAME_PREFERENCE` order is meant (an operational
        frame or link before a joint). :class:`FrameNotFound` (a ``KeyError`` listing close
        names and the robot's frames) if there is none.
        """
        return find_frame(self.model, name, frame_type, self.name)

    def frames(self, pattern: str | None = None) -> list[FrameInfo]:
        """Every frame of the model: id, name, type (``"BODY"`` for a link, ``"JOINT"``,
        ``"FIXED_JOINT"``, ``"OP_FRAME"``, ``"SENSOR"``) and the joint that moves it.

        ``pattern`` keeps the frames whose name contains it, ignoring case
        (``robot.frames("hand")``: the candidates for a hand's end effector).
        """
        return list_frames(self.model, pattern)

    def _warn_q0_on_limits(self) -> None:
        """Warn when the reference configuration puts a joint that moves the end effector
        exactly on a limit of its range (TIAGo's torso lift and first arm joint): a task that
        needs it to move further that way cannot, and a ``PostureTask`` pulls it there."""
        at = at_limits(self.model, self.ee_frame_id, self.q0, self._lower, self._upper)
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
        names = list(names_arg(locked_joints, "locked_joints"))
        model = self.model
        ids = locked_ids(model, names, self.name)
        q_ref = self.q0 if q is None else self.check_q(q)
        reduced, visual, collision, unmimicked, mimics, q0 = reduce_model(
            model, self._unmimicked, self.mimic_joints, self.visual_model, self.collision_model,
            names, ids, q_ref, self.q0, self.name)
        robot = type(self).__new__(type(self))
        robot.__dict__.update(self.__dict__)
        robot._local = threading.local()
        robot.package_dirs = list(self.package_dirs)
        robot.model, robot.visual_model, robot.collision_model = reduced, visual, collision
        kind = model.frames[self.ee_frame_id].type  # the same frame: same name, same type
        same = [i for i, f in enumerate(reduced.frames) if f.name == self.ee_frame
                and f.type == kind]
        robot.ee_frame_id = same[0] if same else robot.frame_id(self.ee_frame)
        robot._units = model_measures.unit_blocks(reduced)
        robot.reach, robot._base_q = model_measures.reach(reduced)
        robot._lower, robot._upper = position_ranges(reduced)
        robot._velocity = model_measures.velocity_limits(reduced)
        robot.velocity_names = model_measures.velocity_names(reduced)
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
        model_measures.warn_far_target(position, origin, self.reach, self.name,
                                       self._base_q is not None, name)

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
        return random_within(self.model, self._lower, self._upper, rng)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, ee_frame={self.ee_frame!r}, nq={self.nq}, nv={self.nv})"
