"""The method protocol: the mapping M(J) of the CLIK law ``q_dot = M(J) (x_dot_d + K e)``.

A method owns one compiled kernel (:mod:`~sjt_pin.kernels`) that computes a whole step's joint
displacement from the stacked task rows, and the numpy form of its matrix for analysis and
tests (the reference formulas are in :mod:`~sjt_pin.mappings`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from .. import kernels as K
from ..gains import Gain


class Method(ABC):
    """A CLIK mapping. Subclasses set ``name``, ``kernel`` and write their parameters."""

    name: ClassVar[str]
    #: transpose-type updates stall at saddles of exactly singular configurations
    stalls: ClassVar[bool] = False
    kernel: ClassVar

    def configure(self, work: np.ndarray, gain: Gain, dt: float, n_chain: int) -> None:
        """Write the kernel's parameters into ``work`` (its ``P_*`` slots)."""
        work[K.P_DT] = dt
        work[K.P_GAIN_MODE] = gain.mode
        work[K.P_GAIN_ARG] = self.gain_argument(gain, n_chain)

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
        return K.FF_TRANSPOSE

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
