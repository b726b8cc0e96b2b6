"""Many set-point IK problems at once: :func:`solve_many` and the stream it is made of,
:func:`solve_chunks`.

The targets are cut into chunks of consecutive targets; each chunk is one task. Target ``k``
(counting from ``first``) is solved with ``rng = numpy.random.default_rng([seed, first + k])``
and, by default, an iteration budget only (:data:`sjt_pin.ik.BUDGET`, no time limit), so a
result depends on the target, its start, ``seed`` and ``first + k`` alone: not on the process,
the machine, the chunking or the executor.

Where the chunks run:

- in this thread (``processes=1``, or a single chunk);
- a pool of worker processes (``processes=N``): each worker receives the solver once, when it
  starts;
- any ``concurrent.futures.Executor`` (``executor=``): Dask's ``client.get_executor()``, a
  ``ThreadPoolExecutor``, ... The first tasks carry the pickled solver; a worker keeps it,
  keyed by a hash of its bytes (one solver per worker thread), and the later tasks carry only
  that key. A worker that has not seen the solver (one that joined late, or restarted) answers
  so at once, and its chunk is sent again with the solver.

Chunks stream: at most ``inflight`` of them are submitted ahead of the results, so a batch
larger than memory can come from an iterator. Each task carries its targets packed as arrays
(``pin.SE3`` as 4x4 matrices) and returns arrays. If a target fails, the batch stops: the
chunks not yet done are cancelled (on every executor; chunks already running finish) and
:class:`BatchError` names the target.
"""

from __future__ import annotations

import hashlib
import itertools
import os
import pickle
import threading
from collections.abc import Iterable, Iterator, Sized
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .ik import IKResult
from .validation import integer

#: targets per chunk: in this process and the pool, and on another executor (fewer, larger
#: tasks for a cluster's scheduler)
CHUNK, EXECUTOR_CHUNK = 64, 1024
#: chunks submitted ahead of the results: per process of the pool, and on another executor
POOL_INFLIGHT, EXECUTOR_INFLIGHT = 4, 64
#: solvers (and their pickled bytes) a worker keeps, most recent first
CACHED = 4


class BatchError(RuntimeError):
    """A target of a batch failed; the batch was stopped and its remaining chunks cancelled.

    Attributes: ``target`` (its index in the batch passed, from 0), ``chunk`` (the range of
    indices of its chunk) and ``error`` (what the solve raised, also ``__cause__``).
    """

    def __init__(self, target: int, start: int, stop: int, error: BaseException):
        super().__init__(target, start, stop, error)
        self.target, self.chunk, self.error = target, range(start, stop), error
        self.__cause__ = error

    def __str__(self) -> str:
        return (f"target {self.target} failed (chunk of targets {self.chunk.start}-"
                f"{self.chunk.stop - 1}; the rest of the batch was cancelled): "
                f"{type(self.error).__name__}: {self.error}")


@dataclass
class BatchPart:
    """The results of consecutive targets ``start, start + 1, ...`` (indices in the batch
    passed, from 0): ``q`` (n, nq), ``success`` (n,) bool, ``iterations`` and ``restarts``
    (n,) int, ``error`` (n,) float (the tasks' error norm, m and rad), ``clipped`` (n tuples:
    the joints whose start was clipped into the limits, see :class:`~sjt_pin.IKResult`)."""

    start: int
    q: np.ndarray
    success: np.ndarray
    iterations: np.ndarray
    error: np.ndarray
    restarts: np.ndarray
    clipped: list[tuple[str, ...]]

    def __len__(self) -> int:
        return len(self.success)

    def results(self) -> list[IKResult]:
        """The part as :class:`~sjt_pin.IKResult` objects."""
        return [IKResult(q, bool(s), int(i), float(e), int(r), c) for q, s, i, e, r, c in
                zip(self.q, self.success, self.iterations, self.error, self.restarts,
                    self.clipped, strict=True)]


# -- the worker's side -----------------------------------------------------------------------------
_MISSING = "sjt-pin: solver not cached here"  # a worker's answer to a key it does not know
_PAYLOADS: dict[str, bytes] = {}  # this process's pickled solvers by key
_LOCK = threading.Lock()
_LOCAL = threading.local()  # this thread's solvers by key: threads never share one's buffers


def _keep(cache: dict, key: str, value) -> None:
    cache.pop(key, None)
    cache[key] = value
    while len(cache) > CACHED:
        cache.pop(next(iter(cache)))


def _cached_solver(key: str, payload: bytes | None):
    """This thread's solver for ``key`` (made from ``payload`` or from the bytes this process
    keeps), or None when neither has it."""
    solvers = getattr(_LOCAL, "solvers", None)
    if solvers is None:
        solvers = _LOCAL.solvers = {}
    if key in solvers:
        return solvers[key]
    with _LOCK:
        if payload is not None:
            _keep(_PAYLOADS, key, payload)
        payload = _PAYLOADS.get(key)
    if payload is None:
        return None
    solver = pickle.loads(payload)
    solver.search()  # the search's buffers, before any solve (and any clock) starts
    _keep(solvers, key, solver)
    return solver


def _init_pool(key: str, payload: bytes) -> None:
    """A pool worker's start: keep the solver's bytes, make its solver."""
    _cached_solver(key, payload)


def _run_chunk(key: str, payload: bytes | None, targets, seeds: np.ndarray, start: int,
               first: int, seed: int, options: dict):
    """One chunk on this thread's solver for ``key``: arrays, or :data:`_MISSING`."""
    solver = _cached_solver(key, payload)
    if solver is None:
        return _MISSING
    return _solve_part(solver, _unpack(targets), seeds, start, first, seed, options)


def _solve_part(solver, targets: list, seeds: np.ndarray, start: int, first: int, seed: int,
                options: dict) -> tuple:
    """Targets ``start, start + 1, ...`` of the batch: (q (n, nq), success, iterations, error,
    restarts) as arrays, and the clipped joints; a failure raises :class:`BatchError` naming
    the target."""
    n = len(targets)
    q = np.empty((n, solver.robot.nq))
    success = np.empty(n, dtype=bool)
    iterations, restarts = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    error = np.empty(n)
    clipped = []
    for k, target in enumerate(targets):
        q0 = seeds if seeds.ndim == 1 else seeds[k]
        try:
            r = solver.solve(target, q0, rng=np.random.default_rng([seed, first + start + k]),
                             **options)
        except Exception as exc:
            raise BatchError(start + k, start, start + n, _portable(exc)) from exc
        q[k], success[k], iterations[k], error[k], restarts[k] = (
            r.q, r.success, r.iterations, r.error, r.restarts)
        clipped.append(r.clipped)
    return q, success, iterations, error, restarts, clipped


def _portable(exc: Exception) -> Exception:
    """``exc``, or a RuntimeError with its text if it cannot travel back (pickle)."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")


def _pack(targets: list):
    """``targets`` for a task: ``pin.SE3`` poses as one (n, 4, 4) array (a fraction of their
    pickled size, and exact), anything else as it is."""
    if targets and all(isinstance(t, pin.SE3) for t in targets):
        return np.array([t.homogeneous for t in targets])
    return targets


def _unpack(targets) -> list:
    if isinstance(targets, np.ndarray):
        return [pin.SE3(T) for T in targets]
    return targets


# -- the driver's side -----------------------------------------------------------------------------
def _progress(total: int | None, show: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="solve_many", unit="pose", disable=not show or None)


def _chunks(targets: Iterable, size: int) -> Iterator[tuple[int, list]]:
    """(start, targets) of consecutive chunks of ``size`` targets."""
    iterator, start = iter(targets), 0
    while block := list(itertools.islice(iterator, size)):
        yield start, block
        start += len(block)


class _Seeds:
    """The starts: one configuration for all targets, or one per target."""

    def __init__(self, solver, q0, count: int | None):
        nq = solver.robot.nq
        if np.iscomplexobj(q0):
            raise ValueError("q0 must be real, got complex values")
        seeds = np.asarray(q0, dtype=float)
        if seeds.ndim == 1:
            seeds = solver.robot.check_q(seeds, "q0").copy()
        elif seeds.ndim != 2 or seeds.shape[1] != nq or (count is not None
                                                         and seeds.shape[0] != count):
            rows = "N" if count is None else count
            raise ValueError(f"q0 must have shape ({nq},) or ({rows}, {nq}), got {seeds.shape}")
        elif not np.all(np.isfinite(seeds)):
            raise ValueError("q0 contains NaN or inf")
        self.seeds = seeds

    def part(self, start: int, size: int) -> np.ndarray:
        if self.seeds.ndim == 1:
            return self.seeds
        if start + size > len(self.seeds):
            raise ValueError(f"q0 has {len(self.seeds)} rows, fewer than the targets")
        return self.seeds[start:start + size]


def _is_dask(executor) -> bool:
    """Whether ``executor`` is Dask's (``client.get_executor()``), by its type's module: the
    core never imports distributed."""
    return type(executor).__module__.split(".")[0] == "distributed"


def solve_chunks(solver, targets: Iterable, q0, *, processes: int | None = None,
                 executor: Executor | None = None, progress: bool = True,
                 chunk: int | None = None, inflight: int | None = None, seed: int = 0,
                 first: int = 0, **options) -> Iterator[BatchPart]:
    """:func:`solve_many` as a stream: a :class:`BatchPart` per chunk, in order, as soon as
    it and every chunk before it are done. Closing the iterator early (``break``, an error)
    cancels the chunks not yet done. The arguments are :func:`solve_many`'s."""
    chunk = None if chunk is None else integer(chunk, "chunk")
    inflight = None if inflight is None else integer(inflight, "inflight")
    seed, first = integer(seed, "seed", 0), integer(first, "first", 0)
    if processes is not None:
        processes = integer(processes, "processes")
    if executor is not None and not isinstance(executor, Executor):
        raise TypeError(f"executor must be a concurrent.futures.Executor (e.g. Dask's "
                        f"client.get_executor()), got {type(executor).__name__}")
    if "rng" in options:
        raise TypeError("rng is not an option of solve_many: target k is solved with "
                        "default_rng([seed, first + k]); pass seed=")
    total = len(targets) if isinstance(targets, Sized) else None
    seeds = _Seeds(solver, q0, total)
    if chunk is None:
        chunk = EXECUTOR_CHUNK if executor is not None else CHUNK
    return _stream(solver, targets, seeds, total, processes, executor, progress, chunk,
                   inflight, seed, first, options)


def _stream(solver, targets, seeds: _Seeds, total, processes, executor, progress, chunk,
            inflight, seed, first, options) -> Iterator[BatchPart]:
    bar = _progress(total, progress)
    try:
        parts = _chunks(targets, chunk)
        local = executor is None and (processes == 1 or (total is not None and total <= chunk))
        if local:
            for start, block in parts:
                part = BatchPart(start, *_solve_part(solver, block, seeds.part(start, len(block)),
                                                     start, first, seed, options))
                bar.update(len(part))
                yield part
            return
        payload = pickle.dumps(solver)
        key = hashlib.sha256(payload).hexdigest()
        if executor is not None:
            yield from _run(executor, key, payload, parts, seeds, inflight or EXECUTOR_INFLIGHT,
                            first, seed, options, bar, send_first=True)
            return
        from concurrent.futures import ProcessPoolExecutor

        workers = processes or os.cpu_count() or 1
        pool = ProcessPoolExecutor(workers, initializer=_init_pool, initargs=(key, payload))
        try:
            yield from _run(pool, key, payload, parts, seeds, inflight or POOL_INFLIGHT * workers,
                            first, seed, options, bar, send_first=False)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    finally:
        bar.close()


def _run(executor: Executor, key: str, payload: bytes, parts, seeds: _Seeds, inflight: int,
         first: int, seed: int, options: dict, bar, send_first: bool) -> Iterator[BatchPart]:
    """The chunks on ``executor``, ``inflight`` at a time, yielded in order."""
    pending: dict[Future, tuple[int, object, np.ndarray]] = {}  # future -> its chunk
    done: dict[int, BatchPart] = {}  # finished chunks by start, waiting for earlier ones
    sent = 0  # chunks submitted with the payload
    extra = {"pure": False} if _is_dask(executor) else {}  # no hashing of each task's arguments

    def submit(start: int, targets, starts: np.ndarray, with_payload: bool) -> None:
        nonlocal sent
        sent += with_payload
        future = executor.submit(_run_chunk, key, payload if with_payload else None, targets,
                                 starts, start, first, seed, options, **extra)
        pending[future] = (start, targets, starts)

    try:
        nxt, exhausted = 0, False
        while True:
            while not exhausted and len(pending) + len(done) < inflight:
                item = next(parts, None)
                if item is None:
                    exhausted = True
                    break
                start, block = item
                # the first round carries the solver; later chunks find it on their worker
                submit(start, _pack(block), seeds.part(start, len(block)),
                       send_first and sent < inflight)
            while nxt in done:
                part = done.pop(nxt)
                nxt += len(part)
                yield part
            if not pending:
                if exhausted and not done:
                    return
                continue
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                start, targets, starts = pending.pop(future)
                answer = future.result()  # a BatchError from the worker is raised here
                if isinstance(answer, str) and answer == _MISSING:
                    submit(start, targets, starts, True)  # again, with the solver
                    continue
                part = BatchPart(start, *answer)
                bar.update(len(part))
                done[start] = part
    finally:
        for future in pending:
            future.cancel()


def solve_many(solver, targets: Iterable, q0, *, processes: int | None = None,
               executor: Executor | None = None, progress: bool = True, chunk: int | None = None,
               inflight: int | None = None, seed: int = 0, first: int = 0,
               **options) -> list[IKResult]:
    """:meth:`~sjt_pin.Solver.solve` for every target, in parallel; results in order.

    Target ``k`` is solved with ``rng = numpy.random.default_rng([seed, first + k])``. With the
    default options (an iteration budget, no time limit) the results are identical bit for bit
    however the batch runs: in this process, in the pool, on any executor (Dask), or cut into
    calls (pass each part's position in the whole as ``first``). An explicit ``timeout=``
    (seconds) gives that up: the result then depends on the speed of the worker.

    Args:
        solver: any solver; each worker uses a copy (``pickle``), so this one is not changed.
        targets: the targets, as ``step`` takes them: a sequence, or any iterable (read one
            chunk at a time).
        q0: one start for every target (nq,), or one per target (N, nq).
        processes: worker processes of a pool made for this call (default: one per core); 1
            solves in this thread. Ignored with ``executor``.
        executor: a ``concurrent.futures.Executor`` to run the chunks on instead, e.g. Dask's
            ``client.get_executor()``: each worker thread unpickles the solver once and keeps
            it (see :mod:`sjt_pin.batch`).
        progress: a progress bar (tqdm) on standard error.
        chunk: targets per task (default 64; 1,024 on an executor).
        inflight: chunks submitted ahead of the results (default: 4 per process of the pool;
            64 on an executor, enough for a cluster of 16-32 worker threads; raise it for a
            larger one).
        seed: the seed of the random restarts (an integer >= 0; see above).
        first: the number of the first target (see above; >= 0).
        options: passed to ``solve`` (``tol``, ``max_iters``, ``budget``, ``timeout``, ...).

    Raises :class:`BatchError` (naming the target) when a solve raises; the chunks not yet done
    are cancelled.
    """
    results: list[IKResult] = []
    for part in solve_chunks(solver, targets, q0, processes=processes, executor=executor,
                             progress=progress, chunk=chunk, inflight=inflight, seed=seed,
                             first=first, **options):
        results.extend(part.results())
    return results
