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
  braking of one joint;
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
- ``frame_velocity``, ``position_rows``, ``rotation_defect``, ``unit_defect``
  (``src/transforms.cpp``): the tasks' small transforms and the door's manifold check of q.
"""

# (transition) the C kernels not yet replaced: collision
from ._core import (  # noqa: E402, F401
    CONTINUE,
    CONVERGED,
    SEARCH_STALLED,
    Controller,
    Family,
    MethodParameters,
    SetPointSearch,
    approach_top,
    check_array,
    frame_velocity,
    jlog6_inverse,
    largest_stoppable,
    mapping_matrix,
    position_rows,
    project,
    rotation_defect,
    scaling_factors,
    search_pose,
    search_table,
    stopping_distance,
    unit_defect,
)
from ._kernels import (  # noqa: F401
    braking_reach,
    collision_rows,
    damper_rows,
    near_pairs,
    refresh_pairs,
    sphere_gaps,
    stoppable_rows,
    witness_rows,
)
from .layout import *  # noqa: E402, F401, F403 (the C step kernels' slots, until removed)

#: status bits of :meth:`Controller.run` (``src/controller.hpp``)
NON_FINITE, STALLED, CONSTRAINED, CONFLICT, ROWS_BROKEN, UNCONVERGED = 1, 2, 4, 8, 16, 32
#: gain modes (:mod:`sjt_pin.gains`)
GAIN_FIXED, GAIN_AUTO = 0, 1

distance_queries = None
#: why :data:`distance_queries` is None
distance_queries_missing: str | None = "coal's queries are made through Pinocchio's bindings"
