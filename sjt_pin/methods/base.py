"""The method protocol: the mapping M(J) of the CLIK law ``q_dot = M(J) (x_dot_d + K e)``.

A built-in method (:class:`~sjt_pin.methods.SJT`, :class:`~sjt_pin.methods.JT`,
:class:`~sjt_pin.methods.JP`, :class:`~sjt_pin.methods.DLS`) is its typed parameters for the
compiled step (:meth:`Method.parameters`): the kernel maps the stacked task rows without
forming M, and gives the constraint stage the method's metric (see
``sjt_pin/kernels/src/method.hpp``). A method of your own is a subclass with ``name`` and
:meth:`Method.matrix`: the compiled step calls it with the first level's weighted rows, maps
them through your matrix and enforces every limit on the result in the same stage, in the
metric of JT (your step unchanged where it is within the limits). Limits are none of a
method's business.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from .. import kernels
from ..tasks.base import Task


class Method:
    """A CLIK mapping. Subclasses set ``name`` and either :meth:`parameters` (built-in) or
    :meth:`matrix` (your own)."""

    name: ClassVar[str] = "method"
    #: the update stalls at saddles of exactly singular configurations, and creeps toward the
    #: flat minima of targets out of reach: the solver watches it (:mod:`sjt_pin.escape`)
    stalls: ClassVar[bool] = False

    def parameters(self) -> kernels.MethodParameters | None:
        """The compiled step's parameters; ``None`` for a method of your own, whose step the
        solver computes from :meth:`matrix`."""
        return None

    def adapt(self, tasks: Sequence[Task], length: float) -> None:  # noqa: B027
        """Adapt the parameters that depend on the solver's tasks: ``tasks`` are its first
        priority level's bound target-taking tasks (every level's where the first has none)
        and ``length`` their characteristic length (m), see
        :func:`~sjt_pin.tasks.pose.tasks_length`. The solver calls it once; nothing by
        default."""

    def bound(self, n_chain: int) -> float | None:
        """A configuration-free bound of lambda_max(J M), or ``None`` if there is none (the
        fixed-gain stability check then computes lambda_max at the configuration)."""
        return None

    def matrix(self, J: np.ndarray) -> np.ndarray:
        """M(J) as an (n, m) matrix of the weighted, masked rows ``J`` (m, n; task units per
        joint unit, rad or m): for a built-in method, the compiled mapping applied to the
        columns of the identity (analysis, tests); a method of your own overrides it.

        The step calls a method of your own once per step, from its compiled stage, with ``J``
        a new C-ordered float64 array (yours to keep). It reads a returned float64 array of C
        or Fortran order (``J.T``) as it is and converts anything else as
        ``numpy.ascontiguousarray(M, dtype=float)`` does; a result of another shape or with
        NaN or inf raises ``ValueError`` naming M(J)."""
        params = self.parameters()
        if params is None:
            raise NotImplementedError(f"{type(self).__name__} must define matrix(J)")
        return kernels.mapping_matrix(params, np.ascontiguousarray(J, dtype=float))

    def scaling_factors(self, J: np.ndarray) -> np.ndarray | None:
        """SJT's alpha_i for the weighted, masked rows ``J``; ``None`` for the other methods."""
        return None

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
