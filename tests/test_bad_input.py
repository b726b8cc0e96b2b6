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
    (None, "q must be a vector of numbers, got None"),  # (on a solver's first step too)
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


def test_a_position_for_a_pose_task_suggests_a_position_task(ur5):
    with pytest.raises(ValueError, match=r"got shape \(3,\) \(a position alone\? a "
                                         "PositionTask takes a 3-vector in m\\)"):
        sjt.SJTSolver(ur5).step(ur5.q0, [0.3, 0.2, 0.4])


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
        sjt.PositionTask(axes="xw")
    with pytest.raises(ValueError, match="axes must be"):
        sjt.PositionTask(axes="xx")
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


# -- configurations on their manifold, shapes naming nq and nv (issues 21 and 22) ------------------
SPIN = """<robot name="spinner">
  <link name="base"/><link name="a"/><link name="tip"/>
  <joint name="spin" type="continuous"><parent link="base"/><child link="a"/>
    <axis xyz="0 0 1"/></joint>
  <joint name="lift" type="revolute"><parent link="a"/><child link="tip"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="2"/></joint>
</robot>"""


def test_shape_errors_name_nq_and_nv(panda):
    with pytest.raises(ValueError, match=r"q must have shape \(8,\): .*nq = 8 .*nv = 8; got "
                                         r"shape \(6,\)"):
        panda.fk(np.zeros(6))
    kinova = sjt.Robot.from_example("kinova")  # continuous joints: nq = 9, nv = 6
    with pytest.raises(ValueError, match=r"nq = 9 coordinates, a velocity nv = 6 \(a "
                                         r"continuous joint has 2 coordinates"):
        sjt.SJTSolver(kinova).step(np.zeros(6), kinova.fk(kinova.q0))


@pytest.mark.parametrize("pair", [(0.5, 0.6), (0.0, 0.0), (3.0, 4.0)])
def test_continuous_pairs_off_the_unit_circle_are_refused(pair):
    robot = sjt.Robot.from_urdf(SPIN)
    q = np.array([*pair, 0.3])
    target = robot.fk(np.array([1.0, 0.0, 0.3]))
    match = r"q\[0:2\] = .* is the \(cos, sin\) pair of joint 'spin': it must have unit norm"
    for call in (lambda: robot.fk(q), lambda: robot.jacobian(q),
                 lambda: sjt.SJTSolver(robot).step(q, target)):
        with pytest.raises(ValueError, match=match):  # before: accepted, det R = 5.6 in fk
            call()
    with pytest.raises(ValueError, match=match.replace("q", "q0", 1)):
        sjt.SJTSolver(robot).solve(target, q)


def test_nearly_unit_pairs_are_normalised_and_loops_pay_nothing():
    robot = sjt.Robot.from_urdf(SPIN)
    angle = 0.7
    q = np.array([np.cos(angle) * (1 + 5e-6), np.sin(angle) * (1 + 5e-6), 0.3])
    R = robot.fk(q).rotation
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-14 and np.linalg.det(R) == pytest.approx(1)
    np.testing.assert_allclose(robot.check_q(q)[:2], [np.cos(angle), np.sin(angle)])
    solver = sjt.SJTSolver(robot, dt=0.01)
    target = robot.fk(np.array([np.cos(1.0), np.sin(1.0), 0.5]))
    for _ in range(300):
        q = solver.step(q, target)  # the returned array is on the manifold
    assert solver.error_norm < 1e-6
    bad = q.copy()  # any array but the one step() returned is checked
    bad[:2] *= 1.5
    with pytest.raises(ValueError, match="unit norm"):
        solver.step(bad, target)


@pytest.mark.parametrize("quaternion", [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.55)])
def test_free_flyer_quaternions_must_have_unit_norm(quaternion):
    talos = sjt.Robot.from_example("talos")
    q = talos.q0.copy()
    q[3:7] = quaternion
    match = r"q\[3:7\] = .* quaternion \(x, y, z, w\) of joint 'root_joint': it must have unit"
    with pytest.raises(ValueError, match=match):  # before: fk gave a non-rotation
        talos.fk(q)
    solver = sjt.SJTSolver(talos, task=sjt.PoseTask(frame="gripper_left_joint"))
    with pytest.raises(ValueError, match=match):  # before: step stood still forever
        solver.step(q, talos.fk(talos.q0, "gripper_left_joint"))


# -- rotations: float32 accepted (projected), beyond 1e-4 refused as before ------------------------
def perturbed_rotation(size: float) -> np.ndarray:
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 0.9)
    return R + size * np.array([[0.3, -0.5, 0.1], [0.2, 0.4, -0.6], [-0.1, 0.5, 0.2]])


@pytest.mark.parametrize("size", [1e-6, 2e-5])
def test_nearly_orthonormal_rotations_are_projected(ur5, size):
    R = perturbed_rotation(size)
    defect = np.abs(R.T @ R - np.eye(3)).max()
    assert 1e-6 < defect < 1e-4  # was refused above 1e-6
    target = pin.SE3(R, np.array([0.3, 0.2, 0.4]))
    pose = sjt.validation.as_pose(target.homogeneous)
    projected = pose.rotation
    assert np.abs(projected.T @ projected - np.eye(3)).max() < 1e-14
    assert np.abs(projected - R).max() < 10 * size  # the nearest rotation
    checked = sjt.validation.check_rigid(target)
    np.testing.assert_allclose(checked.rotation, projected, atol=1e-15)
    float32 = np.asarray(ur5.fk(ur5.q0).homogeneous, dtype=np.float32)
    sjt.SJTSolver(ur5).step(ur5.q0, float32)  # float32 poses step
    line = sjt.Line([0.3, 0.1, 0.4], [0.3, 0.2, 0.4], 1.0, rotation=R)
    assert np.abs(line.rotation.T @ line.rotation - np.eye(3)).max() < 1e-14


def test_rotations_beyond_the_projection_tolerance_are_refused(ur5):
    target = pin.SE3.Identity()
    target.rotation = perturbed_rotation(1e-3)
    with pytest.raises(ValueError, match=r"not a rotation matrix: \|R\^T R - I\| = .* "
                                         r"\(above 0.0001"):
        sjt.SJTSolver(ur5).step(ur5.q0, target)


# -- trajectories --------------------------------------------------------------------------------
def test_trajectories_reject_non_finite_times():
    line = sjt.Line([0, 0, 0], [1, 0, 0], 1.0)
    interpolation = sjt.PoseInterpolation(pin.SE3.Identity(), pin.SE3.Identity(), 1.0)
    circle = sjt.Circle([0, 0, 0], 0.1, 1.0)
    for trajectory in (line, interpolation, circle):
        for t in (np.nan, np.inf, -np.inf):
            with pytest.raises(ValueError, match="t must be finite times in s"):
                trajectory.sample(t)  # before: a NaN pose
        with pytest.raises(ValueError, match="finite times"):
            trajectory.samples(np.array([0.0, np.nan]))


def test_position_only_paths_hold_the_start_orientation(ur5):
    q = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    start = ur5.fk(q)
    line = sjt.Line(start.translation, start.translation + [0, 0.1, 0], 0.5)
    circle = sjt.Circle(start.translation - [0.05, 0, 0], 0.05, 0.5)
    for path in (line, circle):
        assert path.position_only and path.rotation is None
        log = sjt.track(sjt.SJTSolver(ur5), path, q)
        # before: the identity orientation, tracked with a 3.1 rad error
        assert log.error_norm.max() < 1e-4 and not log.diverged
        end = ur5.fk(log.q[-1]).rotation
        assert np.abs(pin.log3(start.rotation.T @ end)).max() < 1e-4
        held = path.holding(start.rotation)
        assert not held.position_only and path.position_only
        np.testing.assert_allclose(held.sample(0.2)[0].rotation, start.rotation)
    assert not sjt.Line([0, 0, 0], [1, 0, 0], 1.0, rotation=np.eye(3)).position_only


# -- units: a target far beyond the reach --------------------------------------------------------
def test_a_target_far_beyond_reach_warns_naming_the_units(ur5):
    near = ur5.fk(ur5.q0)
    far = pin.SE3(near.rotation, near.translation * 1000)  # mm by mistake
    solver = sjt.SJTSolver(ur5)
    with pytest.warns(UserWarning, match=r"target is .* m from the origin, more than 10 times "
                                         r"ur5's reach \(1.\d+ m\): positions are in m"):
        solver.step(ur5.q0, far)
    with pytest.warns(UserWarning, match="check its units"):
        solver.solve(far, ur5.q0, max_iters=5, restarts=0)
    with pytest.warns(UserWarning, match="check its units"):
        sjt.SJTSolver(ur5, task=sjt.PositionTask()).step(ur5.q0, far.translation)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sjt.SJTSolver(ur5).step(ur5.q0, near)
        sjt.SJTSolver(ur5).solve(near, ur5.q0, max_iters=5, restarts=0)


def test_a_humanoids_reach_is_measured_from_its_floating_base():
    talos = sjt.Robot.from_example("talos")
    assert 1.0 < talos.reach < 3.0  # was inf: the free flyer's travel counted
    hand = sjt.PoseTask(frame="gripper_left_joint")
    near = talos.fk(talos.q0, "gripper_left_joint")
    q = talos.q0.copy()
    q[:3] += [500.0, 0.0, 0.0]  # the base walked 500 m: a hand target there is fine
    far = pin.SE3(near.rotation, near.translation + [500.0, 0.0, 0.0])
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sjt.SJTSolver(talos, task=hand).step(q, far)
    with pytest.warns(UserWarning, match="m from the robot's base, more than 10 times"):
        sjt.SJTSolver(talos, task=hand).step(talos.q0, far)


# -- big robots: memory, long lists ----------------------------------------------------------------
def chain(joints: int) -> str:
    links = "".join(f'<link name="l{i}"/>' for i in range(joints + 1))
    body = "".join(
        f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        f'<origin xyz="0 0 0.01"/><axis xyz="0 1 0"/>'
        f'<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>' for i in range(joints))
    return f'<robot name="chain">{links}{body}</robot>'


def test_a_robot_whose_data_would_not_fit_is_refused_up_front():
    with pytest.raises(ValueError, match=r"a pin.Data of this model \(nv = 450\) would take "
                                         r"about \d.\d+ GB, above memory_budget = 2 GB"):
        sjt.Robot.from_urdf(chain(450))
    with pytest.warns(UserWarning, match=r"\(nv = 300\) takes about 0.9\d* GB"):
        robot = sjt.Robot.from_urdf(chain(300))
    assert 0.85e9 < robot.data_bytes < 0.95e9  # measured: 901 MB
    small = sjt.Robot.from_urdf(chain(20))
    assert small.data_bytes < 5e6


def test_long_name_lists_in_errors_are_cut():
    leaves = "".join(f'<link name="leaf{i}"/><joint name="j{i}" type="fixed"><parent '
                     f'link="hub"/><child link="leaf{i}"/></joint>' for i in range(2000))
    star = f'<robot name="star"><link name="hub"/>{leaves}</robot>'
    with pytest.raises(ValueError, match=r"several leaf links \['leaf0', .* and 1988 more\]; "
                                         "pass ee_frame=") as caught:
        sjt.Robot.from_urdf(star)
    assert len(str(caught.value)) < 500  # before: all 2,000 names
    roots = "".join(f'<link name="root{i}"/>' for i in range(500))
    with pytest.raises(sjt.URDFError, match=r"several root links \[.* and 488 more\]"):
        sjt.Robot.from_urdf(f'<robot name="r">{roots}</robot>')
    with pytest.raises(sjt.FrameNotFound) as missing:
        sjt.Robot.from_urdf(star, ee_frame="nope")
    assert len(str(missing.value)) < 1000


@pytest.mark.parametrize("rng", ["x", 1.5, [0.5]])
def test_solve_refuses_a_bad_rng_at_the_door(ur5, rng):
    """A bad ``rng`` is refused even when the first start succeeds (no restart ever draws)."""
    solver = sjt.SJTSolver(ur5)
    target = ur5.fk(ur5.q0)
    assert solver.solve(target, ur5.q0).success  # the first start succeeds
    with pytest.raises(TypeError, match="rng must be"):
        solver.solve(target, ur5.q0, rng=rng)
