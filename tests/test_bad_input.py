"""Every public entry point rejects bad input with an error naming the argument."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt


@pytest.mark.parametrize("q, match", [
    (np.zeros(5), r"q must have shape \(6,\)"),
    (np.zeros((6, 1)), r"q must have shape \(6,\)"),
    (np.array([0, 0, np.nan, 0, 0, 0]), "q contains NaN"),
    ("zeros", "q must be a vector"),
])
def test_bad_configuration(ur5, q, match):
    solver = sjt.SJTSolver(ur5)
    with pytest.raises(ValueError, match=match):
        solver.step(q, ur5.fk(ur5.q0))
    with pytest.raises(ValueError, match=match):
        ur5.fk(q)
    with pytest.raises(ValueError, match=match):
        ur5.jacobian(q)


@pytest.mark.parametrize("target, match", [
    (np.eye(3), r"target must be a pin.SE3 or a 4x4 matrix, got shape \(3, 3\)"),
    (np.full((4, 4), np.nan), "target contains NaN"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), "target rotation is not a rotation"),
    (None, "target must be a pin.SE3"),
])
def test_bad_pose_target(ur5, target, match):
    with pytest.raises(ValueError, match=match):
        sjt.SJTSolver(ur5).step(ur5.q0, target)


def test_bad_position_target_and_velocity(ur5):
    solver = sjt.SJTSolver(ur5, task=sjt.PositionTask())
    with pytest.raises(ValueError, match=r"target must have shape \(3,\)"):
        solver.step(ur5.q0, [0.1, 0.2])
    with pytest.raises(ValueError, match=r"target_velocity must have shape \(6,\)"):
        solver.step(ur5.q0, [0.1, 0.2, 0.3], target_velocity=np.zeros(2))
    with pytest.raises(ValueError, match="target_velocity contains NaN"):
        solver.step(ur5.q0, [0.1, 0.2, 0.3], target_velocity=np.full(6, np.nan))


def test_unknown_frame_lists_close_names(ur5):
    with pytest.raises(sjt.FrameNotFound, match=r"'tool_0' not found .*close names: \['tool0'"):
        sjt.Robot.from_example("ur5", ee_frame="tool_0")
    with pytest.raises(sjt.FrameNotFound, match="wrist_3_link"):
        sjt.SJTSolver(ur5, task=sjt.PoseTask(frame="wrist3_link"))
    with pytest.raises(KeyError):  # FrameNotFound is also a KeyError
        ur5.fk(ur5.q0, frame="nope")


def test_missing_and_malformed_urdf_name_the_file(tmp_path):
    missing = tmp_path / "missing.urdf"
    with pytest.raises(sjt.URDFError, match=f"not found: {missing}"):
        sjt.Robot.from_urdf(missing)
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link name='a'>")
    with pytest.raises(sjt.URDFError, match=f"invalid URDF {broken}: not well-formed XML: "
                                            "Premature end of data in tag link line 1"):
        sjt.Robot.from_urdf(broken)
    with pytest.raises(sjt.URDFError, match="invalid URDF <URDF string>: not well-formed XML"):
        sjt.Robot.from_urdf("<robot name='x'><link name='a'>")
    with pytest.raises(ValueError, match="not an example-robot-data robot; did you mean 'ur5'"):
        sjt.Robot.from_example("ur55")


@pytest.mark.parametrize("kwargs, match", [
    ({"dt": 0.0}, "dt must be a positive number in s"),
    ({"dt": -1e-3}, "dt must be a positive number"),
    ({"dt": np.nan}, "dt must be a positive number"),
    ({"dt": 5e-324}, "dt must be a positive number of normal size"),  # subnormal: NaN steps
    ({"gain": -1.0}, "gain must be a finite number >= 0"),
    ({"gain": np.inf}, "gain must be a finite number >= 0"),
    ({"gain": "fast"}, "gain must be a number, a sequence or 'auto'"),
    ({"gain": [1.0, 2.0]}, r"gain as a sequence must have shape \(6,\)"),
    ({"gain": [1.0] * 5 + [-1.0]}, "gain as a sequence"),
])
def test_bad_solver_settings(ur5, kwargs, match):
    with pytest.raises(ValueError, match=match):
        sjt.SJTSolver(ur5, **kwargs)


def test_bad_task_and_trajectory_arguments():
    with pytest.raises(ValueError, match="axes must be a non-empty subset of 'xyz'"):
        sjt.PositionTask("xw")
    with pytest.raises(ValueError, match="axes must be"):
        sjt.PositionTask("xx")
    with pytest.raises(ValueError, match="weight must be positive"):
        sjt.PoseTask(weight=[1, 1, 1, 1, 1, 0])
    with pytest.raises(ValueError, match=r"weight must have shape \(3,\)"):
        sjt.OrientationTask(weight=[1, 2])
    for make in (sjt.PoseTask, sjt.PositionTask, sjt.PostureTask):
        for weight in (True, "a", None if make is sjt.PostureTask else "1"):
            with pytest.raises(TypeError, match="weight must be"):
                make(weight=weight)
    with pytest.raises(TypeError, match="weight must be numbers"):
        sjt.PositionTask(weight=[True, True, True])
    with pytest.raises(ValueError, match="duration must be a positive number"):
        sjt.Line([0, 0, 0], [1, 0, 0], duration=0)
    with pytest.raises(ValueError, match=r"start must have shape \(3,\)"):
        sjt.Line([0, 0], [1, 0, 0], duration=1)
    with pytest.raises(ValueError, match="radius must be a positive number"):
        sjt.Circle([0, 0, 0], -0.1, duration=1)
    with pytest.raises(ValueError, match="timing must be one of"):
        sjt.PoseInterpolation(pin.SE3.Identity(), pin.SE3.Identity(), 1.0, timing="cubic")


def test_track_rejects_bad_arguments(ur5):
    line = sjt.Line([0.3, 0.1, 0.4], [0.3, 0.2, 0.4], duration=0.1)
    with pytest.raises(ValueError, match=r"q0 must have shape \(6,\)"):
        sjt.track(sjt.SJTSolver(ur5), line, np.zeros(3))
    with pytest.raises(TypeError, match="trajectory must be a Trajectory"):
        sjt.track(sjt.SJTSolver(ur5), [line], ur5.q0)
