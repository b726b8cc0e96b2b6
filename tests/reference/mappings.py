"""The matrices M(J) that map a task velocity to joint velocities: ``q_dot = M(J) v``.

Pure numpy, nothing about robots. ``J`` is an (m, n) task Jacobian (m task rows, n joints).

============  ================================  ==========================================
name          M(J)                              paper
============  ================================  ==========================================
jp            J^+ (Moore-Penrose)               eq. (4), (8)
dls           J^T (J J^T + lambda^2 I)^-1       damped least squares (introduction)
jp, dls + lm  ... + lm I inside the inverse     Levenberg-Marquardt (Sugihara 2011), the
                                                solvers' lm = w |e_w| L
jt            J^T                               eq. (10)
sjt           D J^T, D = diag(alpha_i)          eq. (20)-(21), alpha_i = 1 / (J_i^T J_i)
damped sjt    D J^T (J D J^T + lambda I)^-1     SJT's D as the columns' scale of a damped
                                                least-squares step (this package's default)
============  ================================  ==========================================

They are the tests' reference formulas: the compiled step (``sjt_pin.kernels``) computes
``M(J) v`` without forming M, and ``tests/`` checks it against these.
"""

from __future__ import annotations

import numpy as np

#: Squared column norm below which a joint counts as not moving the task (alpha_i = 0).
COLUMN_TOL = 1e-10

#: Singular values below ``JP_RCOND * sigma_max`` are treated as zero by the pseudoinverse.
JP_RCOND = 1e-12


def scaling_factors(J: np.ndarray, column_tol: float = COLUMN_TOL,
                    length: float = 0.0) -> np.ndarray:
    """SJT scaling factors ``alpha_i = 1 / (J_i^T J_i)`` (eq. 18), 0 for columns with no effect.

    For a revolute joint and a 6-row task ``J_i^T J_i = |z_i x (p_e - p_i)|^2 + 1 >= 1`` (eq. 19),
    so ``0 < alpha_i <= 1``. A column with ``J_i^T J_i <= column_tol`` (a joint outside the chain,
    a finger, a joint whose axis passes through a position-task point) gets ``alpha_i = 0``.
    ``length`` (task units) floors the column norm: ``alpha_i = 1 / max(J_i^T J_i, length^2)``.
    """
    squared_norms = np.einsum("ij,ij->j", J, J)
    active = squared_norms > column_tol
    alpha = np.zeros_like(squared_norms)
    np.divide(1.0, np.maximum(squared_norms, length**2), out=alpha, where=active)
    return alpha


def sjt_matrix(J: np.ndarray, column_tol: float = COLUMN_TOL, length: float = 0.0) -> np.ndarray:
    """``D J^T`` (eq. 20)."""
    return scaling_factors(J, column_tol, length)[:, None] * J.T


def damped_sjt_matrix(J: np.ndarray, damping: float, column_tol: float = COLUMN_TOL,
                      length: float = 0.0) -> np.ndarray:
    """``D J^T (J D J^T + damping I)^-1``: the damped least-squares step on the unit-norm
    columns ``J sqrt(D)``, scaled back by ``sqrt(D)``; ``damping`` > 0 is dimensionless."""
    alpha = scaling_factors(J, column_tol, length)
    A = (J * alpha) @ J.T
    return np.linalg.solve(A + damping * np.eye(J.shape[0]), J * alpha).T


def jt_matrix(J: np.ndarray) -> np.ndarray:
    """``J^T`` (eq. 10)."""
    return J.T.copy()


def jp_matrix(J: np.ndarray, rcond: float = JP_RCOND, lm: float = 0.0) -> np.ndarray:
    """Moore-Penrose pseudoinverse ``J^+`` (eq. 4), from the SVD with relative cutoff ``rcond``;
    with ``lm`` > 0 (task units^2) the singular values above the cutoff are damped:
    ``sigma / (sigma^2 + lm)`` instead of ``1 / sigma``, i.e. ``J^T (J J^T + lm I)^-1`` on
    them (the Levenberg-Marquardt step, whose ``lm`` is ``w |e_w| L``, see
    :class:`~sjt_pin.methods.JP`)."""
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    cutoff = rcond * (s[0] if s.size else 0.0)
    s_inv = np.divide(s, s * s + lm, out=np.zeros_like(s), where=s > cutoff)
    return (Vt.T * s_inv) @ U.T


def dls_matrix(J: np.ndarray, damping: float, lm: float = 0.0) -> np.ndarray:
    """Damped least squares ``J^T (J J^T + (damping^2 + lm) I)^-1``; ``damping`` (lambda) in
    task units (m, rad), ``lm`` >= 0 in task units^2: the Levenberg-Marquardt term
    ``w |e_w| L`` (see :class:`~sjt_pin.methods.DLS`), 0 for the textbook form."""
    m = J.shape[0]
    return np.linalg.solve(J @ J.T + (damping**2 + lm) * np.eye(m), J).T


def max_loop_eigenvalue(J: np.ndarray, M: np.ndarray) -> float:
    """Largest eigenvalue of the loop matrix ``J M`` (m x m).

    The discrete closed loop is ``e_{k+1} = (I - dt K J M) e_k``; with ``K = k I`` it is stable
    iff ``k dt lambda_max(J M) < 2``. ``J M`` is symmetric positive semidefinite for all four
    mappings (for SJT it is ``sum alpha_i J_i J_i^T``, eq. 25, with eigenvalues in [0, n_active]).
    """
    JM = J @ M
    return float(np.linalg.eigvalsh(0.5 * (JM + JM.T))[-1]) if JM.size else 0.0


def stable_gain_bound(J: np.ndarray, M: np.ndarray, dt: float) -> float:
    """Largest scalar gain k (1/s) keeping the linearised loop stable: ``2 / (dt lambda_max)``."""
    lam = max_loop_eigenvalue(J, M)
    return np.inf if lam <= 0.0 else 2.0 / (dt * lam)
