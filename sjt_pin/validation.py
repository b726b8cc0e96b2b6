"""Argument checks of the public entry points: each returns the converted value or raises a
``ValueError``/``TypeError`` that names the argument, what was expected and what came.

Nothing is repaired silently: a complex number is not cast to its real part, a 4x4 matrix whose
last row is not [0 0 0 1] is not a pose, a scaled rotation is not a rotation. Two repairs are
documented and bounded: a rotation within :data:`PROJECT_TOL` of orthonormal (float32 data) is
projected to the nearest rotation, and a unit quaternion or (cos, sin) pair within
:data:`UNIT_TOL` of unit norm is normalised.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .kernels import rotation_defect

#: Largest max|R^T R - I| of a rotation taken as it is (double-precision products of rotations).
RIGID_TOL = 1e-9
#: Largest max|R^T R - I| of a matrix taken as a rotation: between RIGID_TOL and this, it is
#: replaced by the nearest rotation (SVD, the orthogonal Procrustes solution). float32 pipelines
#: (cameras, ROS messages, learned policies) give 1e-7 to 1e-5; beyond 1e-4 it is refused.
PROJECT_TOL = 1e-4
#: Largest |norm - 1| of a unit quaternion (free flyer, spherical joint) or of a continuous or
#: planar joint's (cos, sin) pair in a configuration: within it the block is normalised, beyond
#: it the configuration is refused, naming the joint.
UNIT_TOL = 1e-5
#: Names shown in an error message before the list is cut ("... and N more").
MAX_NAMES = 12


def name_list(names, limit: int = MAX_NAMES) -> str:
    """``names`` as a list for a message, cut after ``limit`` entries ("... and N more")."""
    names = list(names)
    if len(names) <= limit:
        return repr(names)
    shown = ", ".join(map(repr, names[:limit]))
    return f"[{shown}, ... and {len(names) - limit} more]"


def as_vector(value, name: str, size: int | None = None) -> np.ndarray:
    """``value`` as a finite float vector of length ``size`` (any length if None): a
    C-contiguous, aligned float64 array (a copy of a strided view), as the kernels read it."""
    if isinstance(value, (str, bytes)) or value is None:
        raise ValueError(f"{name} must be a vector of numbers, got {value!r}")
    if np.iscomplexobj(value):
        raise ValueError(f"{name} must be real, got complex values {value!r}")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a vector of numbers, got {value!r}") from exc
    if arr.ndim != 1 or (size is not None and arr.shape[0] != size):
        want = f"({size},)" if size is not None else "(n,)"
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf: {arr}")
    return np.require(arr, requirements=("C", "A"))


def configuration(value, name: str, nq: int, nv: int) -> np.ndarray:
    """``value`` as a finite float configuration vector of shape (nq,); a shape error names
    nq (configuration coordinates) and nv (velocities: columns of the Jacobian)."""
    try:
        return as_vector(value, name, nq)
    except ValueError as exc:
        if not str(exc).startswith(f"{name} must have shape"):
            raise
        shape = str(exc).rsplit("got shape ", 1)[-1]
        extra = (" (a continuous joint has 2 coordinates (cos, sin) and 1 velocity, a free "
                 "flyer 7 and 6)" if nq != nv else "")
        raise ValueError(f"{name} must have shape ({nq},): a configuration of this robot holds "
                         f"nq = {nq} coordinates, a velocity nv = {nv}{extra}; got shape "
                         f"{shape}") from None


class UnitBlocks:
    """The blocks of a configuration that must have unit norm: each free flyer's and spherical
    joint's quaternion, each continuous and planar joint's (cos, sin) pair.

    ``blocks`` holds ``(joint name, kind, first index, size)`` per block.
    """

    def __init__(self, blocks: list[tuple[str, str, int, int]]):
        self.blocks = blocks
        self.index = np.array([i for _, _, first, size in blocks
                               for i in range(first, first + size)], dtype=np.intp)
        self.starts = np.cumsum([0] + [size for *_, size in blocks[:-1]], dtype=np.intp)
        self.sizes = np.array([size for *_, size in blocks], dtype=float)
        #: (first, size) of each block, (k, 2) int64: what ``kernels.unit_defect`` takes
        self.layout = np.array([(first, size) for _, _, first, size in blocks],
                               dtype=np.int64).reshape(-1, 2)

    def __bool__(self) -> bool:
        return bool(self.blocks)

    def check(self, q: np.ndarray, name: str) -> np.ndarray:
        """``q`` with each block normalised if its norm is within :data:`UNIT_TOL` of 1 (a new
        array if one changes); ``ValueError`` naming the first joint beyond it."""
        if not self.blocks:
            return q
        values = q[self.index]
        norms = np.sqrt(np.add.reduceat(values * values, self.starts))
        defect = np.abs(norms - 1.0)
        if not np.all(defect <= UNIT_TOL):
            k = int(np.argmax(~(defect <= UNIT_TOL)))
            joint, kind, first, size = self.blocks[k]
            raise ValueError(
                f"{name}[{first}:{first + size}] = {np.round(q[first:first + size], 6).tolist()} "
                f"is the {kind} of joint {joint!r}: it must have unit norm (within "
                f"{UNIT_TOL:g}), its norm is {norms[k]:.6g}")
        if np.all(defect <= 1e-14):
            return q
        q = q.copy()
        q[self.index] = values / np.repeat(norms, self.sizes.astype(np.intp))
        return q


def check_rigid(pose: pin.SE3, name: str = "target") -> pin.SE3:
    """``pose`` unchanged if its rotation is a rotation (within :data:`RIGID_TOL`) and every
    entry is finite; a copy with the nearest rotation if it is within :data:`PROJECT_TOL`."""
    homogeneous = pose.np
    defect = rotation_defect(homogeneous)
    if not defect <= RIGID_TOL:
        if not defect <= PROJECT_TOL:
            _raise_not_rigid(homogeneous, defect, name)
        pose = pin.SE3(nearest_rotation(pose.rotation), pose.translation.copy())
    if not math.isfinite(float(np.abs(pose.translation).sum())):
        raise ValueError(f"{name} contains NaN or inf: translation {pose.translation}")
    return pose


def nearest_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation closest to ``R`` in the Frobenius norm: ``U V^T`` of ``R = U S V^T``
    (``R`` is near a rotation here, so ``det(U V^T) = +1``)."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float))
    return U @ Vt


def _raise_not_rigid(homogeneous: np.ndarray, defect: float, name: str) -> None:
    if not np.all(np.isfinite(homogeneous)):
        raise ValueError(f"{name} contains NaN or inf:\n{homogeneous}")
    if not np.array_equal(homogeneous[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{name} is not a rigid transform: its last row is {homogeneous[3]}, "
                         "not [0 0 0 1]")
    R = homogeneous[:3, :3]
    if np.linalg.det(R) <= 0.0:
        raise ValueError(f"{name} rotation is not a rotation matrix (det = "
                         f"{np.linalg.det(R):.3g}, a reflection or degenerate)")
    raise ValueError(f"{name} rotation is not a rotation matrix: |R^T R - I| = {defect:.3g} "
                     f"(above {PROJECT_TOL:g}, the most that is projected to the nearest "
                     "rotation; a scaled or sheared matrix)")


def as_pose(value, name: str = "target") -> pin.SE3:
    """``value`` (a ``pin.SE3`` or a 4x4 homogeneous matrix) as a rigid, finite ``pin.SE3``."""
    if isinstance(value, pin.SE3):
        return check_rigid(value, name)
    if value is None or isinstance(value, (str, bytes)) or np.iscomplexobj(value):
        raise ValueError(f"{name} must be a pin.SE3 or a 4x4 matrix, got {value!r}")
    try:
        homogeneous = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a pin.SE3 or a 4x4 matrix, got {value!r}") from exc
    if homogeneous.shape != (4, 4):
        hint = (" (a position alone? a PositionTask takes a 3-vector in m)"
                if homogeneous.shape == (3,) else "")
        raise ValueError(f"{name} must be a pin.SE3 or a 4x4 matrix, got shape "
                         f"{homogeneous.shape}{hint}")
    homogeneous = np.ascontiguousarray(homogeneous)
    defect = rotation_defect(homogeneous)
    if not defect <= PROJECT_TOL:
        _raise_not_rigid(homogeneous, defect, name)
    if not np.all(np.isfinite(homogeneous)):
        raise ValueError(f"{name} contains NaN or inf:\n{homogeneous}")
    rotation = homogeneous[:3, :3].copy()
    if not defect <= RIGID_TOL:
        rotation = nearest_rotation(rotation)
    return pin.SE3(rotation, homogeneous[:3, 3].copy())


def as_motion(value, name: str = "target_velocity") -> np.ndarray:
    """``value`` (a ``pin.Motion`` or a 6-vector [linear (m/s), angular (rad/s)]) as a float
    6-vector; finiteness is checked by the step (a NaN shows in the feed-forward)."""
    if (type(value) is np.ndarray and value.shape == (6,) and value.dtype == np.float64
            and value.flags.c_contiguous and value.flags.aligned):
        return value
    if isinstance(value, pin.Motion):
        return value.vector
    return as_vector(value, name, 6)


def axis_rows(axes, name: str = "axes") -> np.ndarray:
    """The world-axis rows (0, 1, 2 for x, y, z) of ``axes``, a non-empty subset of ``"xyz"``
    without repeats, in the order given (int64)."""
    if (not isinstance(axes, str) or not axes or set(axes) - set("xyz")
            or len(set(axes)) != len(axes)):
        raise ValueError(f"{name} must be a non-empty subset of 'xyz', got {axes!r}")
    return np.array(["xyz".index(a) for a in axes], dtype=np.int64)


def positive(value, name: str, unit: str = "") -> float:
    """``value`` as a finite float > 0 (``TypeError`` if it is not a number)."""
    number = real_number(value, name, unit)
    if not math.isfinite(number) or number <= 0.0:
        raise ValueError(f"{name} must be a positive number{' in ' + unit if unit else ''}, "
                         f"got {value!r}")
    return number


def period(value, name: str = "dt") -> float:
    """A control period in s: a positive number of normal size (a subnormal ``dt`` makes
    ``1 / dt`` overflow and the first step NaN)."""
    number = positive(value, name, "s")
    if number < 2.2250738585072014e-308:  # sys.float_info.min
        raise ValueError(f"{name} must be a positive number of normal size in s, got {value!r}")
    return number


def real_number(value, name: str, unit: str = "") -> float:
    """``value`` as a float, or ``TypeError`` naming ``name`` (no bool, str, None or complex)."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None or np.iscomplexobj(value):
        raise TypeError(f"{name} must be a number{' in ' + unit if unit else ''}, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a number{' in ' + unit if unit else ''}, "
                        f"got {value!r}") from exc


def raise_non_finite_targets(targets) -> None:
    """Raise the ``ValueError`` that explains a non-finite task error whose configuration is
    finite: a target holding NaN or inf, or one so far away that the error overflows."""
    for target in targets:
        if target is None:
            continue
        values = target.np if isinstance(target, pin.SE3) else np.asarray(target)
        if not np.all(np.isfinite(values)):
            raise ValueError("target contains NaN or inf")
    raise ValueError("target is too far for a finite task error (a translation above about "
                     "1e150 m overflows): check its units")


def positive_limits(value, size: int, name: str, unit: str) -> np.ndarray:
    """``value`` (a number or ``size`` numbers) as a float vector of positive limits in
    ``unit`` (``inf`` for none)."""
    if isinstance(value, (str, bytes, bool)) or value is None or np.iscomplexobj(value):
        raise TypeError(f"{name} must be a number or {size} numbers in {unit}, got {value!r}")
    limits = np.broadcast_to(np.asarray(value, dtype=float), (size,)).copy() \
        if np.ndim(value) == 0 else np.asarray(value, dtype=float)
    if limits.shape != (size,) or np.any(np.isnan(limits)) or np.any(limits <= 0):
        raise ValueError(f"{name} must be one positive number or {size} (one per velocity "
                         f"coordinate) in {unit}, inf for none; got {value!r}")
    return limits


def integer(value, name: str, minimum: int = 1) -> int:
    """``value`` as an int >= ``minimum`` (a whole float is accepted, a bool is not), or an
    error naming ``name``."""
    whole = (isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
             or isinstance(value, (float, np.floating)) and float(value).is_integer())
    if not whole:
        raise TypeError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def names_arg(value, name: str) -> tuple[str, ...]:
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
