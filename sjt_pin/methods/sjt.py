"""The scaled Jacobian transpose, eq. (20)-(22)."""

from __future__ import annotations

from .. import kernels
from .transpose import TransposeMethod


class SJT(TransposeMethod):
    """``M = D J^T``, ``D = diag(alpha_i)``, ``alpha_i = 1 / (J_i^T J_i)`` (eq. 18, 20-21).

    The alpha_i come from the tasks' own (weighted, stacked) rows and are 0 for joints that do
    not move them: joints outside the frames' kinematic chains, and columns whose squared norm
    is below ``column_tol``. The floor ``length`` l under the column norm,
    ``alpha_i = 1 / max(J_i^T W J_i, l^2)``: pose rows never reach it (``J_i^T W J_i >= L^2``
    for a revolute joint, eq. 19 with the pose task's length L), position-only rows get
    ``|q_dot_i| <= k |e| / l`` instead of an alpha without bound near a joint axis. Either way
    ``alpha_i J_i^T W J_i <= 1``, so the loop matrix ``J D J^T`` has eigenvalues in ``[0, n]``
    whatever the robot's size or length unit (eq. 25) and ``gain < 2 / (n dt)`` is stable at
    every configuration.
    """

    name = "sjt"
    scaled = True

    def bound(self, n_chain):
        if self.feedback == "damped":
            return 1.0
        return float(max(n_chain, 1))  # tr(J D J^T) = n_active <= n_chain

    def scaling_factors(self, J):
        return kernels.scaling_factors(self.parameters(), J)
