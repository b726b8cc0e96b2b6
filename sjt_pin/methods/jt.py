"""The Jacobian transpose, eq. (10)-(11)."""

from __future__ import annotations

from .transpose import TransposeMethod


class JT(TransposeMethod):
    """``M = J^T``: no singularities; the stable gain shrinks with sigma_max(J)^2, so it depends
    on the robot's size and the length unit ("auto" bounds lambda_max(J J^T) at each step)."""

    name = "jt"
