"""The fixed-gain stability check of the discrete CLIK loop.

With a fixed gain K = k I, one step of ``q_dot = M (x_dot_d + K e)`` integrated over ``dt``
maps the error as ``e_next ≈ (I - k dt J M) e``; it shrinks every mode only while
``k dt lambda_max(J M) < 2`` (the discrete counterpart of the paper's stability argument,
Section 3.3: the eigenvalues of ``J M`` are what the gain multiplies). SJT's scaling keeps
``lambda_max(J D J^T)`` at most the number of chain joints, which is why it takes far higher
gains than JT (the paper's Fig. 6).
"""

from __future__ import annotations

import warnings

import numpy as np

from .exceptions import GainWarning


class StabilityCheck:
    """Warn once when a fixed gain exceeds ``2 / (dt lambda_max(J M))`` at the configuration.

    Args:
        method: the solver's :class:`~sjt_pin.methods.Method` (its ``bound`` and ``matrix``).
        n_chain: how many joints the tasks move.
        enabled: whether to check at all.
    """

    def __init__(self, method, n_chain: int, enabled: bool):
        self.method, self.n_chain = method, n_chain
        self.enabled = bool(enabled)
        self.warned = False
        self.armed = False  # whether the next step must run the check

    def arm(self, fixed: bool, k_dt: float) -> bool:
        """Whether the check can fire with a gain whose largest ``k`` times ``dt`` is ``k_dt``
        (``fixed``: a fixed gain; adaptive ones hold the bound themselves): only when
        ``k_dt`` times a bound of lambda_max reaches 2. Sets and returns :attr:`armed`."""
        bound = self.method.bound(self.n_chain)
        self.armed = (self.enabled and not self.warned and fixed
                      and (bound is None or k_dt * bound >= 2.0))
        return self.armed

    def check(self, Jw: np.ndarray, trace: float, k: float, dt: float) -> None:
        """Warn (:class:`~sjt_pin.exceptions.GainWarning`, once) if ``k dt lambda_max(J M)
        >= 2`` for the weighted, masked task rows ``Jw`` (``trace``: tr(J M) of the step, the
        bound when the method has none of its own; ``k``: the largest gain, 1/s)."""
        bound = self.method.bound(self.n_chain)
        if bound is None:
            bound = trace
        if k * dt * bound < 2.0:
            return
        JM = Jw @ self.method.matrix(Jw)
        lam = float(np.linalg.eigvalsh(0.5 * (JM + JM.T))[-1]) if JM.size else 0.0
        if lam <= 0.0 or k * dt * lam < 2.0:
            return
        self.warned, self.armed = True, False
        warnings.warn(
            f"{self.method.name.upper()} gain {k:g} 1/s exceeds the stability bound "
            f"2 / (dt lambda_max(J M)) = {2.0 / (dt * lam):.4g} 1/s at the current "
            f"configuration (dt = {dt:g} s); the closed loop will oscillate or diverge",
            GainWarning, stacklevel=4)  # (check < Solver._slow < Solver.step < caller)
