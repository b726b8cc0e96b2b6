"""The method protocol: the mapping M(J) of the CLIK law ``q_dot = M(J) (x_dot_d + K e)``.

A method is its matrix ``M(J)`` (:meth:`Method.matrix`, numpy; the reference formulas are in
:mod:`~sjt_pin.mappings`). The built-in methods also own a compiled kernel
(:mod:`~sjt_pin.kernels`) that computes a whole step from the stacked task rows in one call; a
method of your own needs only ``name`` and ``matrix``, and its step is computed from the matrix
(:meth:`Method.python_step`). Limits are none of a method's business: the solver's constraint
stage (:mod:`~sjt_pin.constraints`) enforces them after any method, by solving it again on fewer
joints.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import ClassVar

import numpy as np

from .. import kernels
from ..gains import Gain
from ..tasks.base import Task


class Method(ABC):
    """A CLIK mapping. Subclasses set ``name``, ``kernel`` and write their parameters."""

    name: ClassVar[str]
    #: transpose-type updates stall at saddles of exactly singular configurations
    stalls: ClassVar[bool] = False
    #: the compiled step ``(J, e, ff, q, work, step) -> status`` of a built-in method; ``None``
    #: for a method of your own, whose step :meth:`python_step` computes from :meth:`matrix`
    kernel: ClassVar[Callable[..., int] | None] = None

    def configure(self, work: np.ndarray, gain: Gain, dt: float, n_chain: int) -> None:
        """Write the kernel's parameters into ``work`` (its ``P_*`` slots)."""
        work[kernels.P_DT] = dt
        work[kernels.P_GAIN_MODE] = gain.mode
        work[kernels.P_GAIN_ARG] = self.gain_argument(gain, n_chain)

    def adapt(self, tasks: Sequence[Task], length: float) -> None:  # noqa: B027
        """Adapt the parameters that depend on the solver's tasks: ``tasks`` are its bound
        target-taking tasks and ``length`` their characteristic length (m), see
        :func:`~sjt_pin.tasks.pose.tasks_length`. The solver calls it once, before
        :meth:`configure`; nothing by default."""

    def gain_argument(self, gain: Gain, n_chain: int) -> float:
        """The kernel's ``P_GAIN_ARG`` for ``gain``: the factor c of "auto"."""
        return gain.factor

    def bound(self, n_chain: int) -> float | None:
        """A configuration-free bound of lambda_max(J M), or ``None`` if there is none (the
        fixed-gain stability check then uses tr(J M) of the step)."""
        return None

    @abstractmethod
    def matrix(self, J: np.ndarray) -> np.ndarray:
        """M(J) as an (n, m) matrix of the weighted, masked rows ``J`` (analysis, tests)."""

    def scaling_factors(self, J: np.ndarray) -> np.ndarray | None:
        """SJT's alpha_i for the weighted, masked rows ``J``; ``None`` for the other methods."""
        return None

    def feedforward_mode(self) -> int:
        """The kernels' ``P_FF_MODE``: how a desired velocity is mapped."""
        return kernels.FF_TRANSPOSE

    def python_step(self, J: np.ndarray, e: np.ndarray, ff: np.ndarray, q: np.ndarray,
                    work: np.ndarray, step: np.ndarray) -> int:
        """The kernel's contract in numpy, from :meth:`matrix`: ``step = dt M(J_w)
        (ff_w + gain K e_w)`` on the joints of the mask (plus the escape velocity), with
        ``J_w = diag(sw) J`` and "auto" ``gain = c / (dt lambda_max(J_w M))``; writes the
        kernel's results into ``work`` and returns its status bits."""
        m, n = J.shape
        rows, mask_at = int(work[kernels.P_ROWS]), int(work[kernels.P_MASK])
        sw, k = work[rows:rows + m], work[rows + m:rows + 2 * m]
        mask = work[mask_at:mask_at + n]
        dt = work[kernels.P_DT]
        Jw = sw[:, None] * J * mask
        ew = sw * e
        M = np.asarray(self.matrix(Jw), dtype=float)
        loop = float(np.max(np.linalg.eigvals(Jw @ M).real, initial=0.0)) if m else 0.0
        if work[kernels.P_GAIN_MODE] == kernels.GAIN_FIXED:
            gain = 1.0
        else:
            gain = work[kernels.P_GAIN_ARG] / (dt * loop) if loop > 0.0 else 0.0
        v = gain * k * ew
        has_ff = work[kernels.P_HAS_FF] != 0.0
        if has_ff:
            v = v + sw * ff
        step[:] = dt * (M @ v) * mask
        if work[kernels.P_ESCAPING] != 0.0:
            step += dt * work[int(work[kernels.P_EXTRA]):int(work[kernels.P_EXTRA]) + n]
        rows_e = int(work[kernels.P_ERROR_ROWS])
        info = work[kernels.INFO:kernels.INFO + kernels.INFO_SIZE]
        info[kernels.I_E_SQ] = float(e[:rows_e] @ e[:rows_e])
        info[kernels.I_FF_SQ] = float(ff @ ff) if has_ff else 0.0
        info[kernels.I_EW_SQ] = float(ew[:rows_e] @ ew[:rows_e])
        info[kernels.I_GAIN], info[kernels.I_LOOP] = gain, max(loop, 1.0)
        info[kernels.I_STALL] = 1.0
        info[kernels.I_TRACE], info[kernels.I_SCALE] = float(np.trace(Jw @ M)), 1.0
        info[kernels.I_REGULAR] = float(np.linalg.norm(step)) / dt
        finite = np.isfinite(info[kernels.I_E_SQ] + info[kernels.I_FF_SQ])
        return 0 if finite else kernels.NON_FINITE

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
