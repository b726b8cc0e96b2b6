"""The arithmetic of the pose and position tasks: twists seen from a frame, rigidity, rows."""

from __future__ import annotations

import math

from .compile import compiled


@compiled
def frame_velocity(oMf, oMd, velocity, out):
    """The desired velocity (``velocity`` = [p_dot_d, omega_d], world axes at the desired
    origin) as a twist of the frame at ``oMf``, in its LOCAL axes:
    ``[R^T (p_dot_d + omega_d x (p_f - p_d)), R^T omega_d]``; ``oMf``, ``oMd`` are 4x4."""
    d0 = oMf[0, 3] - oMd[0, 3]
    d1 = oMf[1, 3] - oMd[1, 3]
    d2 = oMf[2, 3] - oMd[2, 3]
    w0, w1, w2 = velocity[3], velocity[4], velocity[5]
    v0 = velocity[0] + w1 * d2 - w2 * d1
    v1 = velocity[1] + w2 * d0 - w0 * d2
    v2 = velocity[2] + w0 * d1 - w1 * d0
    for a in range(3):
        out[a] = oMf[0, a] * v0 + oMf[1, a] * v1 + oMf[2, a] * v2
        out[3 + a] = oMf[0, a] * w0 + oMf[1, a] * w1 + oMf[2, a] * w2


@compiled
def rotation_defect(M):
    """max |R^T R - I| of the rotation block of the 4x4 ``M``: 0 for a rigid transform, ``inf``
    when det R <= 0 or the last row is not [0 0 0 1], NaN when R or the translation holds a NaN
    or an inf."""
    defect = 0.0
    for a in range(3):
        for b in range(3):
            acc = -1.0 if a == b else 0.0
            for c in range(3):
                acc += M[c, a] * M[c, b]
            defect = max(defect, abs(acc))
    det = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
           - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
           + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))
    if defect != defect or det != det or not (math.isfinite(M[0, 3]) and math.isfinite(M[1, 3])
                                               and math.isfinite(M[2, 3])):
        return math.nan
    if not det > 0.0 or M[3, 0] != 0.0 or M[3, 1] != 0.0 or M[3, 2] != 0.0 or M[3, 3] != 1.0:
        return math.inf
    return defect


@compiled
def position_rows(J6, oMf, p_d, velocity, out):
    """A position task's rows into ``out`` = [axes (d) | J (d x n) | e (d) | ff (d)]: the
    world-axis rows ``axes`` of the LOCAL_WORLD_ALIGNED Jacobian ``J6``, ``e = p_d - p`` and
    the desired linear velocity (``velocity[:3]``, world axes; not written when ``velocity``
    is empty)."""
    n = J6.shape[1]
    d = (out.shape[0]) // (n + 3)
    for r in range(d):
        a = int(out[r])
        for j in range(n):
            out[d + r * n + j] = J6[a, j]
        out[d + d * n + r] = p_d[a] - oMf[a, 3]
        if velocity.shape[0] >= 3:
            out[2 * d + d * n + r] = velocity[a]
