"""A method of one's own (only its matrix M(J)): the compiled step maps the first level's rows
through it exactly as the built-in methods are mapped, takes "auto"'s gain from the largest
eigenvalue of the symmetric part of J M, and refuses a matrix it cannot use."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.methods import Method

Q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])


class Transpose(Method):
    """J^T (a Fortran-ordered view of J: the step must read it as M, not as its bytes); keeps
    the last rows it was given."""

    name = "own-jt"
    J = None

    def matrix(self, J):
        self.J = J.copy()
        return J.T


class Skewed(Method):
    """J^T A with A = I + a skew part: J M = J J^T A is not symmetric."""

    name = "skewed"
    J = None

    def matrix(self, J):
        self.J = J.copy()
        m = J.shape[0]
        skew = 0.3 * (np.triu(np.ones((m, m)), 1) - np.tril(np.ones((m, m)), -1))
        return J.T @ (np.eye(m) + skew)


class Given(Method):
    """Whatever matrix the test puts in ``value``."""

    name = "given"
    value = None

    def matrix(self, J):
        return self.value


def _target(robot, q, offset=(0.02, -0.01, 0.03)):
    return robot.fk(q) * pin.SE3(pin.exp3(np.array([0.05, 0.0, -0.04])), np.array(offset))


@pytest.mark.parametrize("limits", [{}, {"acceleration_limits": 10.0, "jerk_limits": 5000.0}])
def test_own_transpose_steps_as_the_built_in_jt_with_a_fixed_gain(ur5, limits):
    target = _target(ur5, Q, (0.2, -0.1, 0.15))  # far: the speed limits act
    own = sjt.Solver(ur5, Transpose(), gain=40.0, **limits)
    built_in = sjt.JTSolver(ur5, gain=40.0, **limits)
    q_own = q_built = Q
    for _ in range(300):
        q_own, q_built = own.step(q_own, target), built_in.step(q_built, target)
        np.testing.assert_allclose(q_own, q_built, rtol=0, atol=1e-9)  # (rounding only)
    np.testing.assert_array_equal(own.last.clamped, built_in.last.clamped)


def test_auto_gain_divides_by_lambda_max_of_j_m(ur5):
    """One step: "auto" is K = 1 / (dt lambda_max(J J^T)) exactly, the step the built-in JT
    takes with that gain fixed."""
    dt, target = 1e-3, _target(ur5, Q)
    method = Transpose()
    solver = sjt.Solver(ur5, method, dt=dt, velocity_limits=False)  # (the stage keeps the step)
    solver.step(Q, target)
    lam = np.linalg.eigvalsh(method.J @ method.J.T)[-1]
    assert solver.last.loop_bound == pytest.approx(lam, rel=1e-12)
    assert solver.last.gain == pytest.approx(1.0 / (dt * lam), rel=1e-12)
    built_in = sjt.JTSolver(ur5, dt=dt, gain=1.0 / (dt * lam), velocity_limits=False)
    built_in.step(Q, target)
    assert solver.last.task_scale == 1.0
    np.testing.assert_allclose(solver.last.dq, built_in.last.dq, rtol=1e-12, atol=1e-12)


def test_auto_gain_of_a_non_symmetric_loop_uses_its_symmetric_part(ur5):
    method = Skewed()
    solver = sjt.Solver(ur5, method, velocity_limits=False)
    solver.step(Q, _target(ur5, Q))
    J = method.J
    JM = J @ method.matrix(J)
    assert not np.allclose(JM, JM.T)
    top = np.linalg.eigvalsh(0.5 * (JM + JM.T))[-1]
    assert solver.last.loop_bound == pytest.approx(top, rel=1e-12)
    assert top >= np.linalg.eigvals(JM).real.max() - 1e-12  # Bendixson: the gain is stable side


def test_an_own_pseudoinverse_reaches_the_target(ur5):
    class Pinv(Method):
        name = "pinv"

        def matrix(self, J):
            return np.linalg.pinv(J, rcond=1e-10)

    solver = sjt.Solver(ur5, Pinv())
    target = _target(ur5, Q)
    q = Q
    for _ in range(50):
        q = solver.step(q, target)
    assert solver.last.loop_bound == pytest.approx(1.0, abs=1e-9)  # J J^+ = I
    assert solver.error_norm < 1e-9


@pytest.mark.parametrize("value, message", [
    (np.zeros((6, 5)), "M\\(J\\)"),
    (np.zeros(6), "M\\(J\\)"),
    (np.full((6, 6), np.nan), "NaN or inf"),
    (np.full((6, 6), np.inf), "NaN or inf"),
    (None, "M\\(J\\) must be a 2-D array of floats, got NoneType"),  # (a forgotten return)
    ("abc", "M\\(J\\) must be a 2-D array of floats, got str"),
])
def test_a_matrix_the_step_cannot_use_is_refused(ur5, value, message):
    method = Given()
    method.value = value
    solver = sjt.Solver(ur5, method)
    with pytest.raises((ValueError, TypeError), match=message):
        solver.step(Q, _target(ur5, Q))


class Scribbling(Method):
    """J^T, then writes over the rows it was given and keeps them (they are its own)."""

    name = "scribbling"

    def __init__(self):
        self.given = []

    def matrix(self, J):
        M = J.T.copy()
        self.given.append(J)
        J[:] = np.nan
        return M


def test_the_method_gets_a_new_array_of_its_rows_each_step(ur5):
    """The rows are a new C-ordered float64 array on each call, the method's to keep or write:
    the step is the one a method that leaves them alone takes."""
    method = Scribbling()
    scribbled, plain = sjt.Solver(ur5, method), sjt.Solver(ur5, Transpose())
    target = _target(ur5, Q)
    q_a = q_b = Q
    for _ in range(3):
        q_a, q_b = scribbled.step(q_a, target), plain.step(q_b, target)
        np.testing.assert_array_equal(q_a, q_b)
    first, second = method.given[0], method.given[1]
    assert first is not second and not np.shares_memory(first, second)
    assert first.flags.c_contiguous and first.flags.writeable and first.dtype == np.float64
    assert np.isnan(first).all()


@pytest.mark.parametrize("convert", [lambda M: M.tolist(), np.ascontiguousarray,
                                     lambda M: np.zeros((M.shape[0], 2 * M.shape[1]))[:, ::2] + M])
def test_a_matrix_of_another_layout_is_read_as_its_values(ur5, convert):
    """A list, a C-ordered copy or a strided view of J^T: the same steps as J^T itself."""
    class Converted(Transpose):
        def matrix(self, J):
            return convert(super().matrix(J))

    target = _target(ur5, Q)
    own, reference = sjt.Solver(ur5, Converted()), sjt.Solver(ur5, Transpose())
    q_a = q_b = Q
    for _ in range(5):
        q_a, q_b = own.step(q_a, target), reference.step(q_b, target)
        np.testing.assert_array_equal(q_a, q_b)


def test_an_error_of_the_method_reaches_the_caller_and_changes_nothing(ur5):
    class Failing(Transpose):
        fail = False

        def matrix(self, J):
            if self.fail:
                raise RuntimeError("the method's own error")
            return super().matrix(J)

    method = Failing()
    solver, reference = sjt.Solver(ur5, method), sjt.Solver(ur5, Transpose())
    target = _target(ur5, Q)
    q = solver.step(Q, target)
    q_ref = reference.step(Q, target)
    method.fail = True
    with pytest.raises(RuntimeError, match="the method's own error"):
        solver.step(q, target)
    method.fail = False
    np.testing.assert_array_equal(solver.step(q, target), reference.step(q_ref, target))


def test_the_compiled_call_takes_the_matrix_or_the_function_that_gives_it(ur5):
    """``Controller.run``'s ``matrix``: M as an array of C or Fortran order, or the method's
    function, called with the first level's weighted rows (sqrt(w) J on the moving joints):
    the same step; an array of another dtype given directly is refused at the boundary (only
    what the function returns is converted)."""
    solver = sjt.Solver(ur5, Transpose())
    stack, controller = solver.stack, solver._controller
    kinematics = stack.kinematics
    kinematics.update(Q)
    J, e, _ = stack.task.compute(kinematics, stack.task.target(_target(ur5, Q)), None)
    Jw = stack.sqrt_weight[:, None] * J * stack.chain
    seen = []

    def function(rows):
        seen.append(rows.copy())
        return rows.T

    steps = []
    for matrix in (function, np.ascontiguousarray(Jw.T), np.asfortranarray(Jw.T)):
        controller.reset()
        step = np.zeros(ur5.nv)
        controller.run(J, e, None, Q, step, matrix, None, None, None, None)
        steps.append(step)
    np.testing.assert_array_equal(seen[0], Jw)
    np.testing.assert_array_equal(steps[0], steps[1])
    np.testing.assert_array_equal(steps[0], steps[2])
    with pytest.raises(TypeError, match="M\\(J\\)"):
        controller.run(J, e, None, Q, np.zeros(ur5.nv), Jw.T.astype(np.float32), None, None,
                       None, None)
