"""A solver's tasks, bound to its robot, evaluated into stacked rows at a configuration."""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from .kinematics import Kinematics
from .tasks import ContactTask, PoseTask, PostureTask, Task
from .tasks.base import jlog6_rows

#: the usual target types, which are no mappings (isinstance against Mapping costs 0.2 us)
_NOT_MAPPINGS = (pin.SE3, np.ndarray, list, tuple)


def normalise_tasks(task, posture) -> list[Task]:
    """The task argument of a solver (a task, a list, a ``{frame: task}`` mapping or ``None``
    for a pose task on the end effector), with ``posture`` appended. In a mapping a task
    without a frame (centre of mass, posture, ...) sits under any key, which keys its targets."""
    tasks: list[Task]
    if task is None:
        tasks = [PoseTask()]
    elif isinstance(task, Task):
        tasks = [task]
    elif isinstance(task, Mapping):
        tasks = []
        for frame, t in task.items():
            if not isinstance(t, Task):
                raise TypeError(f"task[{frame!r}] must be a sjt_pin Task, got {type(t).__name__}")
            if not isinstance(frame, str):
                raise TypeError(f"the keys of a {{frame: task}} mapping are frame names (str), "
                                f"got {frame!r}")
            if t.has_frame and t.frame not in (None, frame):
                raise ValueError(f"task[{frame!r}] is on frame {t.frame!r}")
            tasks.append(_keyed(t, frame))
    elif (isinstance(task, Sequence) and not isinstance(task, str) and task
          and all(isinstance(t, Task) for t in task)):
        tasks = list(task)
    else:
        raise TypeError("task must be a sjt_pin Task, a list of tasks or a {frame: task} mapping, "
                        f"got {task!r}")
    if posture is not None:
        if not isinstance(posture, PostureTask):
            raise TypeError(f"posture must be a PostureTask, got {type(posture).__name__}")
        tasks.append(posture)
    return tasks


def ordered_by_level(tasks: list[Task]) -> tuple[list[Task], list[int]]:
    """``tasks`` in the order of their priority levels (0 first; ``None``: after every other
    level), and within a level those that take targets first, then those that do not (a
    contact), a posture last (the rows before it are the level's error); and each task's level
    index (0, 1, ...)."""
    given = sorted({t.priority for t in tasks if t.priority is not None})
    rank = {p: k for k, p in enumerate(given)}
    lowest = len(given)
    levels = [lowest if t.priority is None else rank[t.priority] for t in tasks]
    order = sorted(range(len(tasks)), key=lambda i: (
        levels[i], 2 if isinstance(tasks[i], PostureTask) else int(not tasks[i].takes_target)))
    return [tasks[i] for i in order], [levels[i] for i in order]


def _keyed(task: Task, key: str) -> Task:
    """A copy of ``task`` on frame ``key``, or for a task without a frame, labelled ``key``
    (its targets' key)."""
    task = copy.copy(task)
    if task.has_frame:
        task.frame = key
    else:
        task.label = key
    return task


class TaskStack:
    """Bound tasks and the stacked buffers of their rows.

    ``J`` (m, nv), ``e`` (m,) and ``ff`` (m,) hold every task's rows, level by level
    (:func:`ordered_by_level`); ``levels`` says which rows each priority level has:
    ``(begin, end, identity, targets)`` — ``identity`` for a level that is a posture task's
    rows alone, ``targets`` the level's leading rows of tasks that take targets.
    ``sqrt_weight`` (m,) holds the weights' square roots (``rank_scale``: one over each task's
    largest); ``chain`` (nv,) is 1 for the joints
    that move at least one task (``Task.joints``; a posture task moves all). With a single
    task, :meth:`evaluate` returns that task's own arrays without copying.
    """

    def __init__(self, robot, tasks: list[Task]):
        self.robot = robot
        ordered, task_levels = ordered_by_level([t.bind(robot) for t in tasks])
        self.tasks = ordered
        self.targeted = [t for t in self.tasks if t.takes_target]
        #: the tasks the method's parameters are set from (their length, whether all turn): the
        #: first level's target-taking tasks, so that a lower level's leave the first level's
        #: step as it is; every target-taking task where the first level has none (contacts)
        self.leading = [t for t, lv in zip(self.tasks, task_levels, strict=True)
                        if lv == 0 and t.takes_target] or self.targeted
        if not self.targeted:
            raise ValueError("a solver needs at least one task that takes a target (PoseTask, "
                             "PositionTask, OrientationTask, ...)")
        #: the keys of the targets, in order (a task's frame; tasks on one frame share it)
        self.frames = list(dict.fromkeys(t.key for t in self.targeted))
        self.single = len(self.tasks) == 1
        self.task = self.targeted[0]
        nv = robot.nv
        self.dims = [t.dim for t in self.tasks]
        self.dim = sum(self.dims)
        #: rows of the tasks that take targets (a per-row gain has one entry for each)
        self.target_dim = sum(t.dim for t in self.targeted)
        self.posture_dim = self.dim - self.target_dim
        bounds = np.cumsum([0, *self.dims])
        self.slices = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        #: the priority levels: (begin, end, identity, targets) rows of each, top first
        self.levels: list[tuple[int, int, bool, int]] = []
        #: each level's rows that are an error to report (every task's but a posture's: a
        #: contact's slip counts), StepInfo.levels' error
        self.level_errors: list[tuple[int, int]] = []
        for level in sorted(set(task_levels)):
            members = [k for k, lv in enumerate(task_levels) if lv == level]
            begin, end = self.slices[members[0]].start, self.slices[members[-1]].stop
            targets = sum(self.tasks[k].dim for k in members if self.tasks[k].takes_target)
            kept = sum(self.tasks[k].dim for k in members
                       if not isinstance(self.tasks[k], PostureTask))
            identity = (level > 0 and len(members) == 1
                        and isinstance(self.tasks[members[0]], PostureTask))
            self.levels.append((begin, end, identity, targets))
            self.level_errors.append((begin, begin + kept))
        #: the first rows of the first level's target tasks whose error is a ``log6``
        #: (``Task.log6_error``), whose exact rows the step takes from a rest short of the
        #: target on (:meth:`step_rows`)
        first_end = self.levels[0][0] + self.levels[0][3]
        self.log6_rows = np.array([s.start for t, s in zip(self.tasks, self.slices, strict=True)
                                   if t.takes_target and t.log6_error and s.stop <= first_end],
                                  dtype=np.int64)
        #: trailing rows that are rows of the identity (a posture task's, last): the set-point
        #: search solves the stacked system as diagonal plus low rank, linear in nv
        self.identity_rows = (nv if self.tasks and isinstance(self.tasks[-1], PostureTask)
                              and len(self.tasks) > len(self.targeted) else 0)
        #: the rows the set-point search must bring to zero: every task's before the first
        #: posture task (the targets' and a contact's), a prefix of the stacked rows
        first_posture = next((k for k, t in enumerate(self.tasks) if isinstance(t, PostureTask)),
                             len(self.tasks))
        self.search_dim = int(bounds[first_posture])
        #: the rows of the tasks that take targets (the error a step reports), in order
        self.error_rows = np.concatenate(
            [np.arange(s.start, s.stop) for t, s in zip(self.tasks, self.slices, strict=True)
             if t.takes_target]).astype(np.int64)
        contiguous = np.array_equal(self.error_rows, np.arange(self.target_dim))
        self.J = np.zeros((self.dim, nv))
        self.e = np.zeros(self.dim)
        #: the rows of ``e`` that are the tasks' error (without the posture rows): a view when
        #: they come first, else gathered (:meth:`task_error`)
        self.error = self.e[:self.target_dim] if contiguous else None
        self.ff = np.zeros(self.dim)
        self.sqrt_weight = np.concatenate([np.ones(t.dim) if t.sqrt_weight is None
                                           else t.sqrt_weight for t in self.tasks])
        #: per row, 1 over its task's largest ``sqrt_weight``: the weighted rows times it are
        #: each task's rows on one scale, whatever the tasks' weights (a posture's share)
        self.rank_scale = np.concatenate([np.full(t.dim, 1.0 if t.sqrt_weight is None or not
                                                  t.sqrt_weight.max() > 0.0
                                                  else 1.0 / t.sqrt_weight.max())
                                          for t in self.tasks])
        chain = np.zeros(nv)
        model = robot.model
        for t in self.tasks:
            for j in t.joints(model):
                joint = model.joints[j]  # a mimic joint moves the joint it follows:
                chain[joint.idx_v:joint.idx_v + joint.nvExtended] = 1.0  # nv 0, nvExtended 1
        self.chain = chain
        self.n_chain = int(chain.sum())
        self.kinematics = Kinematics(model)
        #: whether every task is one of the package's, whose rows are C-contiguous float64
        #: arrays (a task of your own may return any array: :meth:`contiguous` converts it)
        self.trusted = all(type(t).__module__.startswith("sjt_pin.") for t in self.tasks)
        #: where each target-taking task sits in ``tasks`` (targets() fills those slots)
        self._slots = [k for k, t in enumerate(self.tasks) if t.takes_target]
        self._aligned = self._slots == list(range(len(self._slots)))
        self._tail = [None] * (len(self.tasks) - len(self.targeted))
        self._frame_set = set(self.frames)
        #: each target-taking task's key and validation, read once here (a property and an
        #: attribute lookup per task cost 0.3 us a step)
        self._readers = [(t.key, t.target) for t in self.targeted]
        # per task: its index, the task, its rows, and whether its Jacobian rows are constant
        # (written here once: a posture task's identity)
        self._plan = []
        #: the held contacts and their rows: :meth:`evaluate` asks their drift back
        self._contacts = [] if self.single else [
            (t, self.slices[k]) for k, t in enumerate(self.tasks) if isinstance(t, ContactTask)]
        for k, t in enumerate(self.tasks):
            rows = self.slices[k]
            if not self.single:  # a task may write its rows straight into the stacked buffers
                t.write_into(self.J[rows], self.e[rows], self.ff[rows])
            if t.constant_jacobian:
                self.J[rows] = t.compute(self.kinematics, None, None)[0]
            self._plan.append((k, t, rows, t.constant_jacobian))

    @staticmethod
    def contiguous(J, e, ff):
        """``(J, e, ff)`` as C-contiguous float64 arrays (the compiled step reads nothing else)."""
        return (np.ascontiguousarray(J, dtype=float), np.ascontiguousarray(e, dtype=float),
                None if ff is None else np.ascontiguousarray(ff, dtype=float))

    def task_error(self, e: np.ndarray) -> np.ndarray:
        """The error rows of the stacked ``e`` (a view when they come first)."""
        return e[:self.target_dim] if self.error is not None else e[self.error_rows]

    def _align(self, values: list) -> list:
        """Per-task values of the target-taking tasks, aligned with :attr:`tasks`."""
        if self._aligned:
            return values + self._tail
        out: list = [None] * len(self.tasks)
        for slot, value in zip(self._slots, values, strict=True):
            out[slot] = value
        return out

    def _mapped(self, target: dict) -> list | None:
        """The targets of a ``{key: target}`` dict with exactly the stack's keys, validated
        and aligned with :attr:`tasks`; ``None`` for any other dict (the general path then
        names what is wrong)."""
        if len(target) != len(self.frames):
            return None
        try:
            values = [read(target[key]) for key, read in self._readers]
        except KeyError:
            return None
        return self._align(values)

    def copy(self) -> TaskStack:
        """An independent stack on the same tasks (its own kinematics and buffers)."""
        return TaskStack(self.robot, self.tasks)

    # -- targets ---------------------------------------------------------------------------
    def targets(self, target, target_velocity=None) -> tuple[list, list | None]:
        """``target`` and ``target_velocity`` validated per task: lists aligned with
        :attr:`tasks` (``None`` for tasks that take no target, and for missing velocities).
        With one task that takes targets, ``target`` may be that target itself."""
        targeted = self.targeted
        kind = type(target)
        if kind is dict and target_velocity is None:  # the usual multi-task step
            mapped = self._mapped(target)
            if mapped is not None:
                return mapped, None
        mapping = kind is dict or (kind not in _NOT_MAPPINGS and isinstance(target, Mapping))
        if len(targeted) == 1 and not mapping:
            task = self.task
            targets = self._align([task.target(target)])
            if target_velocity is None:
                return targets, None
            return targets, self._align([task.velocity(target_velocity)])
        if not mapping:
            if len(self.frames) != 1:
                raise ValueError(f"target must be a {{frame: target}} mapping for frames "
                                 f"{self.frames}")
            target = {self.frames[0]: target}  # several tasks on one frame: one target
            if target_velocity is not None:
                target_velocity = {self.frames[0]: target_velocity}
        try:
            targets = [task.target(target[task.key]) for task in targeted]
        except KeyError:
            targets = []
        if len(targets) != len(targeted) or len(target) != len(self.frames):
            unknown = sorted(map(str, set(target) - set(self.frames)))
            missing = sorted(str(f) for f in set(self.frames) - set(target))
            raise ValueError(f"target must have exactly the frames {self.frames}; "
                             f"missing {missing}, unknown {unknown}")
        targets = self._align(targets)
        if target_velocity is None:
            return targets, None
        if not (type(target_velocity) is dict or isinstance(target_velocity, Mapping)):
            raise ValueError(f"target_velocity must be a {{frame: velocity}} mapping over "
                             f"{self.frames}")
        if len(target_velocity) == len(self.frames):  # the usual case: a velocity per frame
            try:
                every = [task.velocity(target_velocity[task.key]) for task in targeted]
            except KeyError:
                every = []
            if every:
                return targets, self._align(every)
        if not target_velocity.keys() <= self._frame_set:
            unknown = sorted(map(str, set(target_velocity) - self._frame_set))
            raise ValueError(f"target_velocity has frames {unknown} that are not task frames "
                             f"{self.frames}")
        velocities: list = [task.velocity(target_velocity[task.key])
                            if task.key in target_velocity else None for task in targeted]
        return targets, self._align(velocities)

    # -- rows --------------------------------------------------------------------------------
    def step_rows(self, J: np.ndarray, e: np.ndarray, exact: bool) -> np.ndarray:
        """The rows a step took: ``J`` itself, or where the step took ``exact`` rows, ``J`` with
        the first level's ``log6`` errors' rows ``Jlog6 J`` (a copy)."""
        if not (exact and self.log6_rows.size):
            return J
        J = J.copy()
        for r in self.log6_rows:
            J[r:r + 6] = jlog6_rows(e[r:r + 6], J[r:r + 6])
        return J

    def evaluate(self, q: np.ndarray, targets: list, velocities: list | None,
                 motion: tuple[np.ndarray, float] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(J, e, ff)`` stacked at ``q`` (validated by the caller); ``ff`` is ``None`` when
        there are no velocities. The arrays are reused by the next call. ``motion``: the last
        step's velocity (nv,) and the period (s); with it, held contacts' rows ask back the
        drift a step at that velocity makes (:meth:`ContactTask.drift
        <sjt_pin.tasks.ContactTask.drift>`)."""
        kinematics = self.kinematics
        kinematics.update(q)
        if self.single:
            return self.task.compute(kinematics, targets[0],
                                     None if velocities is None else velocities[0])
        J, e, ff = self.J, self.e, self.ff
        if velocities is None:  # (the loop below without its feed-forward's tests)
            for k, task, rows, constant in self._plan:
                Jt, et, _ = task.compute(kinematics, targets[k], None)
                if et.base is not e:
                    e[rows] = et
                if not constant and Jt.base is not J:
                    J[rows] = Jt
            if motion is None or not self._contacts or not motion[0].any():
                return J, e, None
            return self._drifts(kinematics, motion, True)
        for k, task, rows, constant in self._plan:
            velocity = velocities[k]
            Jt, et, fft = task.compute(kinematics, targets[k], velocity)
            if et.base is not e:  # not written in place
                e[rows] = et
            if not constant and Jt.base is not J:
                J[rows] = Jt
            if velocity is not None and fft is not None:
                if fft.base is not ff:
                    ff[rows] = fft
            elif not constant:
                ff[rows] = 0.0
        if motion is not None and self._contacts and motion[0].any():
            return self._drifts(kinematics, motion, False)
        return J, e, ff

    def _drifts(self, kinematics: Kinematics, motion: tuple[np.ndarray, float], clear: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The stacked rows with the held contacts' drift (m/s, rad/s) in ``ff``, the other
        rows' zero where ``clear`` (no velocities were given)."""
        ff = self.ff
        if clear:
            ff[:] = 0.0
        kinematics.velocity_products(motion[0])
        for task, rows in self._contacts:
            ff[rows] = task.drift(kinematics, motion[1])
        return self.J, self.e, ff

    def search_rows(self, q: np.ndarray, targets: list) -> tuple[np.ndarray, np.ndarray]:
        """``(J, e)`` at ``q`` for the set-point search: as :meth:`evaluate`, with each task's
        rows replaced by the exact rows of its error (:meth:`Task.error_jacobian`)."""
        J, e, _ = self.evaluate(q, targets, None)
        if self.single:
            return self.task.error_jacobian(J), e
        exact = J.copy()
        for _, task, rows, _ in self._plan:
            exact[rows] = task.error_jacobian(J[rows])
        return exact, e

    def poses(self):
        """The task frames' world poses at the last evaluation: one ``pin.SE3``, or a
        ``{frame: pin.SE3}`` dict with several target-taking tasks."""
        if len(self.targeted) == 1:
            return self.task.placement
        return {t.key: t.placement for t in self.targeted}
