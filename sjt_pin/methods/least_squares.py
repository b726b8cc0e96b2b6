"""What JP and DLS share: a least-squares solve in task space."""

from __future__ import annotations

from .. import kernels as K
from .base import Method


class LeastSquaresMethod(Method):
    """``M = J^+`` or ``J^T (J J^T + lambda^2 I)^-1``: the loop eigenvalues are at most 1, so
    "auto" is ``k = c / dt``."""

    kernel = staticmethod(K.least_squares_step)
    damping = 0.0
    rcond = 0.0

    def configure(self, work, gain, dt, n_chain):
        super().configure(work, gain, dt, n_chain)
        work[K.P_MU] = self.damping
        work[K.P_RCOND] = self.rcond

    def bound(self, n_chain):
        return 1.0
