"""Small helpers shared by the tests."""


def regulate(solver, q, target, steps):
    """Step toward a fixed ``target`` until the error is below 1e-7 or ``steps`` have run."""
    for _ in range(steps):
        q = solver.step(q, target)
        if solver.last.error_norm < 1e-7:
            break
    return q
