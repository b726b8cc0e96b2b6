"""The gain K of the CLIK law ``q_dot = M (x_dot_d + K e)``: fixed, or chosen at every step.

The discrete loop ``e_{k+1} = (I - dt K J M) e_k`` is stable iff ``k dt lambda_max(J M) < 2``
(K = k I). So:

- a number (or one per task row): K as given, in 1/s;
- ``"auto"`` (:class:`AutoGain`): ``k = c / (dt lambda_hat)`` at every step, with
  ``lambda_hat >= lambda_max(J M)``: 1 for JP, DLS and the damped SJT, whose loop eigenvalues
  are at most 1; for the transpose feedbacks of JT and SJT an upper bound within a few per
  cent of lambda_max (:func:`~sjt_pin.kernels.loop_bound`); for a method of your own the
  largest eigenvalue of the symmetric part of J M (at least the real part of each eigenvalue
  of J M, lambda_max itself where J M is symmetric). With ``c = 1`` the fastest mode of
  the linearised loop settles in one step without overshoot, and the gain stays below the
  stability bound ``2 / (dt lambda_max)`` by at least a factor 2, guaranteed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .kernels import GAIN_AUTO, GAIN_FIXED
from .validation import real_number

#: c of the automatic gain: c = 1 puts the fastest mode of the linearised loop at rest in one
#: step (no overshoot), half the stability bound.
AUTO_FACTOR = 1.0


class Gain:
    """A gain mode: ``mode`` (the kernels' code), per-row factors ``rows(m)`` and ``factor``."""

    mode: int = GAIN_FIXED
    factor: float = 1.0

    def rows(self, dim: int, extra: int) -> np.ndarray:
        """K's diagonal for ``dim`` task rows and ``extra`` posture rows (1/s, or relative)."""
        return np.ones(dim + extra)

    @property
    def largest(self) -> float:
        """The largest entry of a fixed K (1/s); inf for the modes that choose K themselves."""
        return np.inf

    @property
    def argument(self):
        """What ``gain=`` was given to make this gain (the object itself unless simpler)."""
        return self


class FixedGain(Gain):
    """K as given: a number (K = k I) or one number per task row, in 1/s, >= 0."""

    value: float | np.ndarray  #: K: one number, or one per task row (1/s)

    def __init__(self, value: float | Sequence[float], dim: int | None = None):
        if np.ndim(value) == 0:
            k = real_number(value, "gain", "1/s")
            if not np.isfinite(k) or k < 0:
                raise ValueError(f"gain must be a finite number >= 0 (1/s), got {value!r}")
            self.value = k
        else:
            if np.iscomplexobj(value):
                raise TypeError(f"gain must be real, got {value!r}")
            arr = np.asarray(value, dtype=float)
            dim = arr.size if dim is None else dim
            if arr.shape != (dim,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(
                    f"gain as a sequence must have shape ({dim},) (one per task row) "
                    f"with finite entries >= 0, got {value!r}")
            self.value = arr.copy()

    def rows(self, dim, extra):
        if np.ndim(self.value) == 0:
            return np.full(dim + extra, self.value)
        # posture rows take the mean gain
        return np.concatenate([self.value, np.full(extra, float(np.mean(self.value)))])

    @property
    def largest(self):
        return float(np.max(self.value))

    @property
    def argument(self):
        return self.value

    def __repr__(self):
        return repr(self.value if np.ndim(self.value) == 0 else self.value.tolist())


class AutoGain(Gain):
    """``k = factor / (dt lambda_hat)`` with ``lambda_hat >= lambda_max(J M)`` at the current
    configuration; ``0 < factor < 2`` (default :data:`AUTO_FACTOR`; 2 is the stability bound)."""

    mode = GAIN_AUTO

    def __init__(self, factor: float = AUTO_FACTOR):
        factor = real_number(factor, "factor")
        if not 0.0 < factor < 2.0:
            raise ValueError(f"factor must be in (0, 2) (2 is the stability bound), got {factor}")
        self.factor = factor

    @property
    def argument(self):
        return "auto" if self.factor == AUTO_FACTOR else self

    def __repr__(self):
        return "'auto'" if self.factor == AUTO_FACTOR else f"AutoGain({self.factor:g})"


def as_gain(value, dim: int) -> Gain:
    """``value`` (a :class:`Gain`, ``"auto"``, a number or a sequence of ``dim`` numbers) as a
    :class:`Gain`."""
    if (isinstance(value, FixedGain) and isinstance(value.value, np.ndarray)
            and value.value.size != dim):
        raise ValueError(f"gain has {value.value.size} rows, the tasks have {dim}")
    if isinstance(value, Gain):
        return value
    if isinstance(value, str):
        if value == "auto":
            return AutoGain()
        raise ValueError(f"gain must be a number, a sequence or 'auto', got {value!r}")
    if value is None:
        raise TypeError("gain must be a number (1/s), a sequence or 'auto', got None")
    return FixedGain(value, dim)
