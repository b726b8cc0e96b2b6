"""Analysis of a mapping M(J): motion ellipsoids (paper Section 3.3) and stability bounds.

Pure numpy on the matrices of :meth:`sjt_pin.methods.Method.matrix`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def max_loop_eigenvalue(J: np.ndarray, M: np.ndarray) -> float:
    """Largest eigenvalue of the loop matrix ``J M`` (m x m): the discrete loop
    ``e_{k+1} = (I - dt K J M) e_k`` is stable iff ``k dt lambda_max(J M) < 2``."""
    JM = J @ M
    return float(np.linalg.eigvalsh(0.5 * (JM + JM.T))[-1]) if JM.size else 0.0


@dataclass
class MotionEllipsoid:
    """Image of the unit input sphere under a transformation T = U Sigma V^T (paper Fig. 1).

    ``axes`` (k, k) holds the principal directions (columns of U) and ``sigma`` the semi-axis
    lengths, largest first.
    """

    sigma: np.ndarray
    axes: np.ndarray

    @property
    def sigma_max(self) -> float:
        return float(self.sigma[0])

    @property
    def sigma_min(self) -> float:
        return float(self.sigma[-1])

    def outline(self, points: int = 100) -> np.ndarray:
        """Points (points, k) on a 2-D ellipse: ``T u`` for unit vectors u (k = 2 only)."""
        if self.axes.shape[0] != 2:
            raise ValueError("outline() draws 2-D ellipses only")
        angle = np.linspace(0.0, 2.0 * np.pi, points)
        circle = np.stack([np.cos(angle), np.sin(angle)])
        return (self.axes @ (self.sigma[:, None] * circle)).T


def motion_ellipsoid(T: np.ndarray) -> MotionEllipsoid:
    """Motion ellipsoid of ``T`` (e.g. ``J^T`` or ``D J^T``, paper eq. 31-32) from its SVD."""
    U, sigma, _ = np.linalg.svd(np.asarray(T, dtype=float), full_matrices=False)
    return MotionEllipsoid(sigma=sigma, axes=U)


def linear_gain_bound(jacobians, matrices, dt: float) -> float:
    """``k_lin = 2 / (dt max_t lambda_max(J M))`` over a sequence of (J, M) pairs (1/s)."""
    lam = max(max_loop_eigenvalue(J, M) for J, M in zip(jacobians, matrices, strict=True))
    return np.inf if lam <= 0 else 2.0 / (dt * lam)
