"""solve_many on a real Dask cluster (``distributed.LocalCluster``, 2 worker processes of one
thread): the same answers as one process, the pool and shards; streaming, progress, a failing
target named and the rest of the batch cancelled; the core does not import Dask."""

import time
from concurrent.futures import Executor, Future, ProcessPoolExecutor

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import batch
from sjt_pin.bench.ik import problems

distributed = pytest.importorskip("distributed", reason="pip install -e '.[cluster]'")


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=40)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="module")
def batch_problem():
    """200 reachable Panda poses from random starts, and 4 beyond its reach (each uses the
    whole iteration budget)."""
    robot = sjt.Robot.from_example("panda")
    pairs = problems(robot, 200, seed=11)
    far = [pin.SE3(np.eye(3), np.array([1.5 + 0.1 * k, 0.0, 0.5])) for k in range(4)]
    targets = [t for t, _ in pairs[:100]] + far + [t for t, _ in pairs[100:]]
    seeds = np.array([s for _, s in pairs[:100]] + [robot.q0] * 4 + [s for _, s in pairs[100:]])
    return sjt.SJTSolver(robot), targets, seeds


def assert_same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.q, y.q)
        assert (x.success, x.iterations, x.error, x.restarts, x.clipped) == \
            (y.success, y.iterations, y.error, y.restarts, y.clipped)


def test_default_arguments_give_the_same_answers_everywhere(client, batch_problem):
    """One process, the pool, Dask (the executor and its chunks) and shards with first=: the
    same q, bit for bit, with the default arguments."""
    solver, targets, seeds = batch_problem
    alone = sjt.solve_many(solver, targets, seeds, processes=1, progress=False)
    assert sum(r.success for r in alone) >= 195 and not any(r.success for r in alone[100:104])
    pool = sjt.solve_many(solver, targets, seeds, processes=2, progress=False)
    dask = sjt.solve_many(solver, targets, seeds, executor=client.get_executor(), chunk=16,
                          progress=False)
    shards = [sjt.solve_many(solver, targets[a:b], seeds[a:b], executor=client.get_executor(),
                             first=a, progress=False) for a, b in ((0, 70), (70, 204))]
    for results in (pool, dask, shards[0] + shards[1]):
        assert_same(results, alone)


def test_a_stream_of_targets_in_order_with_progress(client, batch_problem, monkeypatch):
    """Targets from an iterator, read chunk by chunk with few chunks in flight; the parts come
    in order and the bar counts every pose."""
    solver, targets, seeds = batch_problem
    counted = []

    class Bar:
        def update(self, n):
            counted.append(n)

        def close(self):
            pass

    monkeypatch.setattr(batch, "_progress", lambda total, show: Bar())
    parts = list(sjt.solve_chunks(solver, iter(targets), seeds, executor=client.get_executor(),
                                  chunk=10, inflight=3))
    assert [p.start for p in parts] == list(range(0, 204, 10))
    assert sum(counted) == 204 and sum(len(p) for p in parts) == 204
    reference = sjt.solve_many(solver, targets, seeds, processes=1, progress=False)
    assert_same([r for p in parts for r in p.results()], reference)


def test_a_failing_target_is_named_and_the_rest_cancelled(client, batch_problem):
    """The first chunk fails; the 99 behind it (unreachable targets: each uses the whole
    budget) are cancelled, not run. The budget is 20,000 iterations here (some 30 ms a target,
    0.1 s a chunk): a worker's chunks then outlast the time the cancellation takes to reach it
    on a loaded two-core machine (at the default 2,000, 20 of 64 chunks ran there before it
    did, under the coverage of the whole suite)."""
    solver, targets, seeds = batch_problem
    far = targets[100]
    bad = [far, pin.SE3(np.eye(3), np.array([np.nan, 0.0, 0.0]))] + [far] * 398
    executed = client.run(lambda dask_worker: dask_worker.state.executed_count)
    with pytest.raises(sjt.BatchError, match=r"target 1 failed \(chunk of targets 0-3") as err:
        sjt.solve_many(solver, bad, solver.robot.q0, executor=client.get_executor(), chunk=4,
                       progress=False, budget=20_000)
    assert err.value.target == 1 and err.value.chunk == range(0, 4)
    assert isinstance(err.value.error, ValueError) and "NaN" in str(err.value.error)

    def waiting(dask_scheduler):  # tasks of the batch still queued or running
        return [key for key, task in dask_scheduler.tasks.items()
                if task.state not in ("memory", "erred", "released", "forgotten")]

    deadline = time.monotonic() + 60
    while left := client.run_on_scheduler(waiting):
        assert time.monotonic() < deadline, f"tasks of the batch still to run: {left}"
        time.sleep(0.1)
    after = client.run(lambda dask_worker: dask_worker.state.executed_count)
    ran = sum(after[w] - executed[w] for w in after)
    assert ran < 20  # of 64 submitted chunks: those that had started when the error came


class FirstOnly(Executor):
    """Runs the first task it is given; the others wait (pending) until cancelled."""

    def __init__(self):
        self.futures = []

    def submit(self, fn, *args, **kwargs):
        future = Future()
        if not self.futures:
            try:
                future.set_result(fn(*args, **kwargs))
            except Exception as exc:
                future.set_exception(exc)
        self.futures.append(future)
        return future


def test_a_failing_target_cancels_the_queued_chunks_of_any_executor(ur5):
    solver = sjt.SJTSolver(ur5)
    targets = [ur5.fk(ur5.q0)] * 40
    targets[1] = pin.SE3(np.eye(3), np.array([0.0, np.inf, 0.0]))
    executor = FirstOnly()
    with pytest.raises(sjt.BatchError, match="target 1 failed"):
        sjt.solve_many(solver, targets, ur5.q0, executor=executor, chunk=2, inflight=5,
                       progress=False)
    assert len(executor.futures) == 5  # the stream stopped: 15 chunks were never submitted
    assert all(f.cancelled() for f in executor.futures[1:])


def test_a_worker_without_the_solver_gets_it_again(ur5):
    """Only the first ``inflight`` chunks carry the solver: a worker that has not seen it (here
    a fresh process for every task) says so and gets its chunk again with the solver."""
    solver = sjt.SJTSolver(ur5)
    pairs = problems(ur5, 8, seed=3)
    targets, seeds = [t for t, _ in pairs], np.array([s for _, s in pairs])
    with ProcessPoolExecutor(1, max_tasks_per_child=1) as executor:
        fresh = sjt.solve_many(solver, targets, seeds, executor=executor, chunk=2, inflight=2,
                               progress=False)
    assert_same(fresh, sjt.solve_many(solver, targets, seeds, processes=1, progress=False))


def test_reach_on_the_cluster_by_its_address(client, tmp_path):
    """``sjt-pin reach --scheduler ADDRESS`` gives the map one process gives."""
    from sjt_pin.cli import main
    from sjt_pin.reach import ReachMap, reachability

    out = tmp_path / "map.npz"
    assert main(["reach", "panda", "--step", "0.4", "--orientations", "2", "--quiet",
                 "--scheduler", client.scheduler.address, "--out", str(out),
                 "--html", str(tmp_path / "map.html")]) == 0
    on_dask = ReachMap.load(out)
    alone = reachability(sjt.Robot.from_example("panda"), 0.4, 2, processes=1, progress=False)
    assert on_dask.complete and on_dask.reached.any()
    np.testing.assert_array_equal(on_dask.reached, alone.reached)
    np.testing.assert_array_equal(on_dask.q, alone.q)
