"""The limit protocol: a constraint on each step's joint displacement.

After the method has computed a step, every limit tests it (:meth:`Limit.violated`, one
compiled call) and, only when it is violated, makes it admissible (:meth:`Limit.enforce`). A new
limit is one subclass; see the README's "Extend it".
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np

#: ``remap(free, fixed_velocity)``: the method's step recomputed with only the joints of
#: ``free`` (nv,) moving, the others moving at ``fixed_velocity`` (nv,; rad/s or m/s): the
#: task velocity ``J fixed_velocity`` they provide is taken off the free joints' share.
Remap = Callable[[np.ndarray, np.ndarray], np.ndarray]


class Limit(ABC):
    """A constraint on the displacement ``step = q_dot dt`` (nv,) from configuration ``q``."""

    @abstractmethod
    def violated(self, q: np.ndarray, step: np.ndarray, dt: float) -> bool:
        """Whether ``step`` from ``q`` breaks this limit (cheap: called at every step)."""

    @abstractmethod
    def enforce(self, q: np.ndarray, step: np.ndarray, dt: float, remap: Remap) -> np.ndarray:
        """An admissible step close to ``step`` (may modify and return ``step``)."""
