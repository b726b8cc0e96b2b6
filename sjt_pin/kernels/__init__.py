"""Compiled inner loops (numba): each stage of a step in one call instead of a dozen numpy calls.

On arrays of 6 x n numbers every numpy call costs about 0.3 us whatever it computes, so a step
would spend more in call overhead than in arithmetic. Each function here does its whole loop in
one compiled call; ``tests/test_kernels.py`` checks them against the numpy reference formulas of
:mod:`sjt_pin.mappings` and against Pinocchio. They are compiled on first use and cached in a
per-user folder (:data:`~.compile.CACHE_DIR`), never inside the installed package.

- :mod:`.layout`: where a solver's parameters, constants, results and scratch sit in its
  ``work`` vector, and the status bits a step returns;
- :mod:`.linalg`: small dense linear algebra (Gram matrices, Cholesky, Jacobi eigenvalues, the
  loop-eigenvalue bound);
- :mod:`.methods`: one step of each family of CLIK mappings, limits test included;
- :mod:`.tasks`: the arithmetic of the pose and position tasks;
- :mod:`.limits`: the clamping of joints at their position limits.
"""

from .layout import *  # noqa: F403 (the slot names are the kernels' vocabulary)

# the entry points the rest of the package calls, re-exported
from .limits import clamp_pass  # noqa: F401
from .linalg import cholesky_solve, loop_bound, symmetric_eigen  # noqa: F401
from .methods import least_squares_step, transpose_step  # noqa: F401
from .tasks import frame_velocity, position_rows, rotation_defect  # noqa: F401
