"""Compiled inner loops: each stage of a step in one call instead of a dozen numpy calls.

On arrays of 6 x n numbers every numpy call costs about 0.3 us whatever it computes, so a step
would spend more in call overhead than in arithmetic. The kernels are C++17 on Eigen, bound
with nanobind (``src/``: one file per idea, built by ``pip install`` through CMake; nothing is
compiled at run time). Every array a kernel takes is checked before it is read
(``src/array.hpp``: float64, C-contiguous, aligned, the expected shape); parameters cross the
boundary by name (typed records such as :class:`MethodParameters`), never as slots of a flat
vector. The numpy references that pin them are in ``tests/``.

- :class:`Controller`: one CLIK step after the tasks (``src/controller.hpp``): the method on the
  stacked rows level by level, the escape's velocity, each joint's box from the position, speed,
  acceleration and jerk limits (``src/bounds.hpp``, ``src/braking.hpp``), a user's bounds and
  rows, and the projection (``src/projection.hpp``); its state and results are named fields;
- :class:`MethodParameters`, :class:`Family`: a method's parameters (``src/method.hpp``);
  :func:`mapping_matrix`, :func:`scaling_factors`: the method's M(J) and SJT's alpha_i;
- :func:`project`: the stage's projection on its own (tests, ``solve()``'s user limits);
- :func:`stopping_distance`, :func:`largest_stoppable`, :func:`approach_top`: the jerk-limited
  braking of one joint; :func:`least_widening`: how far the acceleration and jerk limits yield
  to a row no velocity within them meets (``src/bounds.hpp``);
- :func:`check_array`: the boundary's check, on its own;
- :class:`SetPointSearch` (``src/search.hpp``): the set-point search of ``solve()``, one object
  per search holding its parameters (the damping, the method's column tolerance, SJT's floor
  length, whether columns are scaled, a posture task's identity rows), the options of a solve
  and the state of a start as named fields, its current point and next step as arrays;
  ``iterate(J, e, q)`` is one Levenberg-Marquardt iteration on SJT's normalised columns within
  the joint limits; :func:`search_pose`: every iteration of one start on a single pose task in
  one call (it calls Pinocchio's Jacobian once per iteration); :func:`search_table`: the nearest
  starts of the restart table of :mod:`sjt_pin.restarts` in turn; ``CONTINUE``, ``CONVERGED``,
  ``SEARCH_STALLED``: what an iteration reports;
- ``jlog6_inverse(xi, out)`` (``src/lie.cpp``): ``Jlog6(N^-1)`` from ``xi = log6(N)``, the
  exact derivative of a pose error in the rows of its Jacobian (the search's model);
- ``symmetric_eigen(H, values, vectors)`` (``src/symmetric_eigen.cpp``): the eigenvalues and
  eigenvectors of H's symmetric part (the saddle escape's curvature test);
- ``frame_velocity``, ``position_rows``, ``rotation_defect``, ``unit_defect``
  (``src/transforms.cpp``): the tasks' small transforms and the door's manifold check of q;
- the collision limit's kernels (:mod:`sjt_pin.limits.collision`, ``src/collision.hpp``):
  ``damper_rows``: its velocity-damper rows from its pairs' closest points (a row of norm at
  most ``ROUNDING_LEVER`` set to 0; a pair inside its margin pushed out only by a row whose
  lever is at least ``PUSH_LEVER``);
  ``stoppable_rows``: their bounds cut to closing speeds the acceleration limits can stop (also
  a user's rows with room, :mod:`sjt_pin.constraints`), and
  ``braking_reach``: each pair's influence for an arm with acceleration limits
  (``src/collision_braking.cpp``); ``witness_rows``: the rows of its pairs' remembered closest
  points (and their memory); ``near_pairs``: the pairs it must query, or whether its broad
  phase must run again (its state a :class:`Skip`); ``sphere_gaps``: its broad phase's gaps
  between the pairs' bounding spheres; ``refresh_pairs``: its candidates and pairs to query
  after that broad phase, floors aged; ``collision_rows``: a step's exact distance queries
  (Pinocchio's ``computeDistance``, called back through Python), witness and damper rows in one
  call (its tables a :class:`CollisionTables`).
"""

from ._core import (  # noqa: F401
    CONTINUE,
    CONVERGED,
    PUSH_LEVER,
    ROUNDING_LEVER,
    SEARCH_STALLED,
    CollisionTables,
    Controller,
    Family,
    MethodParameters,
    SetPointSearch,
    Skip,
    approach_top,
    braking_reach,
    check_array,
    collision_rows,
    damper_rows,
    frame_velocity,
    jlog6_inverse,
    largest_stoppable,
    least_widening,
    mapping_matrix,
    near_pairs,
    position_rows,
    project,
    refresh_pairs,
    rotation_defect,
    scaling_factors,
    search_pose,
    search_table,
    sphere_gaps,
    stoppable_rows,
    stopping_distance,
    symmetric_eigen,
    unit_defect,
    witness_rows,
)

#: status bits of :meth:`Controller.run` (``src/controller.hpp``)
NON_FINITE, STALLED, CONSTRAINED, CONFLICT, ROWS_BROKEN, UNCONVERGED = 1, 2, 4, 8, 16, 32
#: gain modes (:mod:`sjt_pin.gains`)
GAIN_FIXED, GAIN_AUTO = 0, 1
