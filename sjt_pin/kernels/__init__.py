"""Compiled inner loops: each stage of a step in one call instead of a dozen numpy calls.

On arrays of 6 x n numbers every numpy call costs about 0.3 us whatever it computes, so a step
would spend more in call overhead than in arithmetic. The kernels are plain C on the CPython
API (``src/``: one C file per idea, ``kernels.h`` their shared declarations), compiled once by
``pip install`` — nothing is compiled at run time — and called with numpy arrays through the
buffer protocol. ``tests/test_kernels.py`` checks them
against the numpy reference formulas of :mod:`sjt_pin.mappings` and against Pinocchio.

- :mod:`.layout`: where a solver's parameters, constants, results and scratch sit in its
  ``work`` vector, the status bits a step returns, and the search's state;
- ``transpose_step(J, e, ff, q, work, step)``: one step of a Jacobian-transpose-type CLIK law
  (JT eq. 10, SJT eq. 21, and the damped forms: ``D J_w^T (J_w D J_w^T + lambda I)^-1``), then
  the position box and speed test; ``least_squares_step``: the pseudoinverse (eq. 8) or damped
  least squares; both return the status bits of :mod:`.layout`. A work vector laid out with
  ``Layout(..., smooth=True)`` makes them run the acceleration/jerk constraint stage too (its
  reference: :mod:`sjt_pin.constraints` and :mod:`sjt_pin.limits`);
- ``search_iteration(...)``: one Levenberg-Marquardt iteration of ``solve()`` on SJT's
  normalised columns, within the joint limits; ``search_pose(...)``: every iteration of one
  start on a single pose task in one call (it calls Pinocchio's Jacobian once per iteration),
  or, given the restart table of :mod:`sjt_pin.restarts`, its nearest starts in turn;
  ``jlog6_inverse(xi, out)``: ``Jlog6(N^-1)`` from ``xi = log6(N)``, the exact derivative of a
  pose error in the rows of its Jacobian (the search's model);
- ``damper_rows``: the collision limit's velocity-damper rows from its pairs' closest points;
  ``stoppable_rows``: their bounds cut to closing speeds the acceleration limits can stop;
  ``witness_rows``: the rows of its pairs' remembered closest points (and their memory);
  ``near_pairs``: the pairs it must query, or whether its broad phase must run again;
  ``sphere_gaps``: its broad phase's gaps between the pairs' bounding spheres;
  ``refresh_pairs``: its candidates and pairs to query after that broad phase, floors aged;
  ``collision_rows``: a step's exact distance queries (through Pinocchio's ``computeDistance``,
  or :data:`distance_queries`' compiled ones), witness and damper rows in one call;
  ``distance_queries(shapes, pairs, requests, joints, placements)``: coal's distance queries
  of a limit's pairs in C++ (``src/distances.cpp``, on coal's shapes, each placed at its
  joint's pose times its placement) for ``collision_rows`` to call without Python; None where
  that module is not built or was built against another coal (:data:`distance_queries_missing`
  says why);
  ``braking_reach``: each pair's influence for an arm with acceleration limits;
- ``frame_velocity``, ``position_rows``, ``rotation_defect``: the tasks' small transforms;
- ``follow_motion(step, dt, dq, ddq)``: the velocity and acceleration a step commands (the
  motion state a user's limits read);
- ``project_rows(dq, Jw, A, b, lower, upper, moving, out)``: the constraint stage's smallest
  correction onto general rows and a box (:func:`sjt_pin.constraints.project`), on its dual by
  ``nonnegative_qp(Q, r, y)`` (Lawson and Hanson's NNLS, as
  :func:`sjt_pin.constraints.nonnegative_qp`); ``rows_step(J, q, A, b, lower, upper, work,
  step)``: a kernel step checked against a user's rows and bounds, projected in place when
  it breaks a row (the solver's path for collision dampers); ``smooth_rows_step(J, q, A, b,
  lower, upper, previous, work, step)``: the same for a step of the acceleration/jerk stage,
  projected within its hard and smoothness boxes, its motion state kept (the solver's path for
  a user's limits beside acceleration limits);
- ``cholesky_solve``, ``loop_bound``, ``symmetric_eigen``: the small dense linear algebra,
  exposed for the tests.
"""

from ._kernels import (  # noqa: F401
    braking_reach,
    cholesky_solve,
    collision_rows,
    damper_rows,
    follow_motion,
    frame_velocity,
    jlog6_inverse,
    least_squares_step,
    loop_bound,
    near_pairs,
    nonnegative_qp,
    position_rows,
    project_rows,
    refresh_pairs,
    rotation_defect,
    rows_step,
    search_iteration,
    search_pose,
    smooth_rows_step,
    sphere_gaps,
    stoppable_rows,
    symmetric_eigen,
    transpose_step,
    unit_defect,
    witness_rows,
)
from .layout import *  # noqa: F403 (the slot names are the kernels' vocabulary)

distance_queries = None
#: why :data:`distance_queries` is None (None when it is not)
distance_queries_missing: str | None = None
try:  # (libcoal and Boost.Python are loaded by coal's import first: the module links them)
    import coal as _coal  # noqa: F401

    from ._distances import queries as distance_queries  # type: ignore[no-redef]  # noqa: F401
except ImportError as exc:
    distance_queries_missing = str(exc)
