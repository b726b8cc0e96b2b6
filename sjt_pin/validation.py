"""Argument checks of the public entry points: each returns the converted value or raises a
``ValueError``/``TypeError`` that names the argument, what was expected and what came.

Nothing is repaired silently: a complex number is not cast to its real part, a 4x4 matrix whose
last row is not [0 0 0 1] is not a pose, a scaled rotation is not a rotation.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .kernels import rotation_defect

#: Largest |R^T R - I| accepted as a rotation (targets are often built in float32).
RIGID_TOL = 1e-6


def as_vector(value, name: str, size: int | None = None) -> np.ndarray:
    """``value`` as a finite float vector of length ``size`` (any length if None)."""
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
    return arr


def check_rigid(pose: pin.SE3, name: str = "target") -> pin.SE3:
    """``pose`` unchanged if its rotation is a rotation and every entry is finite."""
    homogeneous = pose.np
    defect = rotation_defect(homogeneous)
    if not defect <= RIGID_TOL:
        _raise_not_rigid(homogeneous, defect, name)
    if not math.isfinite(float(np.abs(pose.translation).sum())):
        raise ValueError(f"{name} contains NaN or inf: translation {pose.translation}")
    return pose


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
                     f"(above {RIGID_TOL:g}; a scaled or sheared matrix)")


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
        raise ValueError(f"{name} must be a pin.SE3 or a 4x4 matrix, got shape {homogeneous.shape}")
    homogeneous = np.ascontiguousarray(homogeneous)
    defect = rotation_defect(homogeneous)
    if not defect <= RIGID_TOL:
        _raise_not_rigid(homogeneous, defect, name)
    if not np.all(np.isfinite(homogeneous)):
        raise ValueError(f"{name} contains NaN or inf:\n{homogeneous}")
    return pin.SE3(homogeneous[:3, :3].copy(), homogeneous[:3, 3].copy())


def as_motion(value, name: str = "target_velocity") -> np.ndarray:
    """``value`` (a ``pin.Motion`` or a 6-vector [linear (m/s), angular (rad/s)]) as a float
    6-vector; finiteness is checked by the step (a NaN shows in the feed-forward)."""
    if type(value) is np.ndarray and value.shape == (6,) and value.dtype == np.float64:
        return value
    if isinstance(value, pin.Motion):
        return value.vector
    return as_vector(value, name, 6)


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
