"""The damped feed-forward of the transpose methods: bounded through singular configurations,
and unit-free."""

import numpy as np
import pytest

import sjt_pin as sjt


def through_the_wrist(ur5):
    """A reachable path on which UR5's wrist passes q5 = 0 (joints 4 and 6 aligned)."""
    a = np.array([0.3, -1.2, 1.5, -1.8, 0.25, 0.2])
    b = a.copy()
    b[4] = -0.25
    return a, sjt.PoseInterpolation(ur5.fk(a), ur5.fk(b), 2.0)


@pytest.mark.parametrize("options", [{}, {"feedback": "transpose"}],
                         ids=["damped", "transpose feedback"])
def test_tracks_a_line_through_a_singular_configuration(ur5, options):
    q0, path = through_the_wrist(ur5)
    damped = sjt.track(sjt.SJTSolver(ur5, dt=1e-3, **options), path, q0)
    paper = sjt.track(sjt.SJTSolver(ur5, dt=1e-3, feedback="transpose",
                                    feedforward="transpose"), path, q0)
    assert not damped.diverged and np.all(np.isfinite(damped.q))
    assert np.min(np.abs(damped.q[:, 4])) < 0.01  # the wrist went through q5 = 0
    assert damped.max_error < 1e-5  # bounded, and small
    assert damped.max_error < paper.max_error / 20  # the paper's D J^T x_dot_d lags far behind


@pytest.mark.parametrize("feedback", ["damped", "transpose"])
def test_unit_free_rescaling_every_task_row_changes_nothing(ur5, feedback):
    """Rows multiplied by s (weight s^2): J sqrt(D) is unchanged, so are the damped solve, its
    Levenberg-Marquardt term |e| sqrt(max alpha), SJT's feedback D J^T K e and the automatic
    gain; the arm moves the same."""
    q0, path = through_the_wrist(ur5)
    logs = [sjt.track(sjt.SJTSolver(ur5, dt=1e-3, feedback=feedback,
                                    task=sjt.PoseTask(weight=s**2)), path, q0)
            for s in (1.0, 10.0)]
    np.testing.assert_allclose(logs[0].q, logs[1].q, atol=1e-9)


def test_the_paper_form_is_one_keyword_away(ur5):
    paper = sjt.SJTSolver(ur5, feedback="transpose", feedforward="transpose", length=0.0)
    assert (paper.method.feedback, paper.method.feedforward) == ("transpose", "transpose")
    with pytest.raises(ValueError, match="needs feedforward='damped'"):
        sjt.SJTSolver(ur5, feedforward="transpose")  # the damped feedback damps both
    with pytest.raises(ValueError, match="feedback must be one of"):
        sjt.SJTSolver(ur5, feedback="pid")
