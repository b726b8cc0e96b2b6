"""Robot: a Pinocchio model of a URDF robot with a chosen end-effector frame.

Kinematic quantities follow Pinocchio's conventions: ``fk`` returns the world pose of a frame
(``oMf``), ``jacobian`` its 6 x nv frame Jacobian [linear; angular] in the frame's own (LOCAL) axes.
"""

from __future__ import annotations

import difflib
import importlib.resources
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from .exceptions import FrameNotFound, URDFError
from .joint_ranges import position_ranges
from .mimic import MimicJoint, apply_mimics, joint_values, reduced_configuration
from .urdf_check import URDFSource, load_model, read_urdf, urdf_mimics
from .validation import as_vector

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
    "z1": "gripperMover",
    "xarm7": "link_eef",
}


#: guards Pinocchio's global random generator (seeded and drawn by random_configuration)
_PINOCCHIO_RNG = threading.Lock()


class Robot:
    """A kinematic model (``pin.Model``) with one end-effector frame.

    Build one with :meth:`from_example`, :meth:`from_urdf` or :meth:`planar3`. ``model``, ``data``,
    ``visual_model`` and ``collision_model`` are Pinocchio's own objects; ``data`` is this robot's
    scratch space, overwritten by every kinematic call.
    """

    def __init__(
        self,
        model: pin.Model,
        ee_frame: str,
        *,
        q0: np.ndarray | None = None,
        name: str | None = None,
        visual_model: pin.GeometryModel | None = None,
        collision_model: pin.GeometryModel | None = None,
        urdf: str | None = None,
        package_dirs: Sequence[str] = (),
        mimic_joints: Sequence[MimicJoint] = (),
    ):
        self.model = model
        #: the mimic relations of ``model``'s mimic joints (see :mod:`sjt_pin.mimic`)
        self.mimic_joints: list[MimicJoint] = list(mimic_joints)
        #: ``model`` before its mimic joints were made (what a pickled robot carries)
        self._unmimicked: pin.Model | None = None
        self._local = threading.local()  # one pin.Data per thread: queries never race
        self.name = name or model.name
        self.visual_model = visual_model
        self.collision_model = collision_model
        self.urdf = urdf  #: the URDF file path or XML text the model came from
        self.package_dirs = list(package_dirs)
        self.ee_frame_id = self.frame_id(ee_frame)
        self.ee_frame = ee_frame
        self._lower, self._upper = position_ranges(model)
        limit = np.asarray(model.velocityLimit, dtype=float)
        self._velocity = np.where((limit > 0) & (limit < 1e30), limit, np.inf)
        #: name of the joint of each velocity (tangent) index: columns of J, entries of dq
        self.velocity_names: list[str] = [
            model.names[j] for j in range(1, model.njoints) for _ in range(model.joints[j].nv)]
        # without a reference configuration: the neutral one, clipped into the limits
        self.q0 = (np.clip(pin.neutral(model), self._lower, self._upper) if q0 is None
                   else self._inside(self.check_q(q0, "q0")))

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
    def from_example(cls, name: str, ee_frame: str | None = None) -> Robot:
        """Load ``name`` from example-robot-data (``"panda"``, ``"ur5"``, ``"talos_full"``, ...).

        ``ee_frame`` defaults to :data:`DEFAULT_EE_FRAMES` for the robots listed there.
        ``q0`` is the robot's reference configuration from its SRDF. Mimic joints (Panda's
        second finger, TALOS's grippers) are Pinocchio mimic joints, as in :meth:`from_urdf`.
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
        if ee_frame is None:
            ee_frame = DEFAULT_EE_FRAMES.get(name)
            if ee_frame is None:
                raise ValueError(
                    f"no default ee_frame for {name!r}; pass ee_frame= (defaults exist for "
                    f"{sorted(DEFAULT_EE_FRAMES)})"
                )
        wrapper = erd.load(name)
        model, q0, mimics = _with_mimics(wrapper.model, wrapper.q0, getattr(wrapper, "urdf", None))
        robot = cls(
            model,
            ee_frame,
            q0=q0,
            mimic_joints=mimics,
            name=name,
            visual_model=wrapper.visual_model,
            collision_model=wrapper.collision_model,
            urdf=getattr(wrapper, "urdf", None),
        )
        robot._unmimicked = wrapper.model if mimics else None
        return robot

    @classmethod
    def from_urdf(
        cls,
        path_or_xml: str | Path | bytes,
        ee_frame: str | None = None,
        package_dirs: Sequence[str | Path] | None = None,
        *,
        load_visuals: bool = True,
    ) -> Robot:
        """Load a URDF from a file path (``str`` or ``pathlib.Path``) or from XML text (a string,
        or UTF-8 bytes, starting with ``<``).

        ``ee_frame`` defaults to the URDF's only leaf link; with several leaves it must be given.
        ``package_dirs`` (folders, or one folder) resolve ``package://`` mesh paths (the URDF's
        folder is always searched). Visual geometry is loaded when its meshes can be found;
        ``load_visuals=False`` skips it.

        The URDF is checked before Pinocchio parses it (:mod:`sjt_pin.urdf_check`): a broken
        one raises :class:`URDFError` naming the file and the joint or link at fault. A joint
        with ``<mimic>`` becomes a Pinocchio mimic joint without a coordinate of its own
        (:mod:`sjt_pin.mimic`); ``lower == upper`` locks a joint at that value
        (:mod:`sjt_pin.joint_ranges`); a planar joint moves in the plane normal to its
        ``<axis>`` (:mod:`sjt_pin.planar`).
        """
        source = read_urdf(path_or_xml)
        model, mimics, unmimicked = load_model(source)
        if isinstance(package_dirs, (str, Path)):
            package_dirs = [package_dirs]  # one folder, not a sequence of characters
        dirs = [str(p) for p in (package_dirs or [])]
        if source.path is not None:
            dirs.append(str(source.path.resolve().parent))
        if ee_frame is None:
            ee_frame = _only_leaf_body(model, source.label)
        visual = _visual_model(model, source, dirs) if load_visuals else None
        urdf = source.text if source.path is None else str(source.path)
        robot = cls(model, ee_frame, visual_model=visual, urdf=urdf, package_dirs=dirs,
                    mimic_joints=mimics)
        robot._unmimicked = unmimicked if mimics else None
        return robot

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
    def frame_id(self, name: str) -> int:
        """Index of frame ``name``; :class:`FrameNotFound` (listing close names) if absent."""
        if not isinstance(name, str) or not self.model.existFrame(name):
            raise FrameNotFound(str(name), [f.name for f in self.model.frames], self.name)
        return self.model.getFrameId(name)

    def check_q(self, q, name: str = "q") -> np.ndarray:
        """``q`` as a finite real vector of shape (nq,), or ``ValueError`` naming ``name``."""
        return as_vector(q, name, self.model.nq)

    @property
    def data(self) -> pin.Data:
        """Pinocchio's scratch space of the calling thread (``fk``/``jacobian`` use it)."""
        data = getattr(self._local, "data", None)
        if data is None:
            data = self._local.data = self.model.createData()
        return data

    def fk(self, q, frame: str | None = None) -> pin.SE3:
        """World pose of ``frame`` (default: the end effector) at configuration ``q``.

        Safe to call from several threads (each has its own ``pin.Data``).
        """
        q = self.check_q(q)
        fid = self.ee_frame_id if frame is None else self.frame_id(frame)
        data = self.data
        pin.forwardKinematics(self.model, data, q)
        return pin.updateFramePlacement(self.model, data, fid)

    def jacobian(self, q, frame: str | None = None,
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
    raise ValueError(f"{source} has several leaf links {leaves}; pass ee_frame=")
