"""Argument checks shared by the public entry points (DESIGN.md section 5).

Each function returns the converted value or raises ``ValueError`` naming the argument.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def as_vector(value, name: str, size: int | None = None) -> np.ndarray:
    """``value`` as a finite float vector of length ``size`` (any length if None)."""
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


def as_pose(value, name: str = "target") -> pin.SE3:
    """``value`` (a ``pin.SE3`` or a 4x4 homogeneous matrix) as a finite ``pin.SE3``.

    A ``pin.SE3`` is returned as it is (its rotation is Pinocchio's to keep; the solvers detect a
    NaN target from the non-finite error it produces, so the hot path pays nothing for it); a
    matrix is checked for NaN/inf and must hold a rotation.
    """
    if isinstance(value, pin.SE3):
        return value
    try:
        homogeneous = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a pin.SE3 or a 4x4 matrix, got {value!r}") from exc
    if homogeneous.shape != (4, 4):
        raise ValueError(f"{name} must be a pin.SE3 or a 4x4 matrix, got shape {homogeneous.shape}")
    if not np.all(np.isfinite(homogeneous)):
        raise ValueError(f"{name} contains NaN or inf")
    rotation = homogeneous[:3, :3]
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6) or np.linalg.det(rotation) < 0:
        raise ValueError(f"{name} rotation is not a rotation matrix")
    return pin.SE3(rotation.copy(), homogeneous[:3, 3].copy())


def as_motion(value, name: str = "target_velocity") -> pin.Motion:
    """``value`` (a ``pin.Motion`` or a 6-vector [linear, angular]) as a finite ``pin.Motion``."""
    vector = value.vector if isinstance(value, pin.Motion) else value
    vector = as_vector(vector, name, 6)
    return value if isinstance(value, pin.Motion) else pin.Motion(vector)


def positive(value, name: str, unit: str = "") -> float:
    """``value`` as a finite float > 0."""
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a positive number, got {value!r}") from exc
    if not np.isfinite(number) or number <= 0.0:
        raise ValueError(f"{name} must be a positive number{' in ' + unit if unit else ''}, "
                         f"got {value!r}")
    return number
