"""Small helpers shared by the tests."""

import numpy as np


def regulate(solver, q, target, steps):
    """Step toward a fixed ``target`` until the error is below 1e-7 or ``steps`` have run."""
    for _ in range(steps):
        q = solver.step(q, target)
        if solver.last.error_norm < 1e-7:
            break
    return q


def full_range_pair(robot, seed, pair):
    """The ``pair``-th (start, goal) configuration pair drawn over the full URDF ranges from
    ``numpy.random.default_rng(seed)``, as ``sjt-pin bench reach`` draws its random reaches."""
    rng = np.random.default_rng(seed)
    for _ in range(pair + 1):
        start, goal = robot.random_configuration(rng), robot.random_configuration(rng)
    return start, goal
