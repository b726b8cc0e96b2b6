"""The collision limit's compiled entries (C++ on Eigen, sjt_pin/kernels/src/*.cpp) at their
boundary: every array argument given strided, reversed, as a stride-12 view of a byte buffer,
Fortran-ordered, too short, read-only where written, of the wrong dtype, byte-swapped, as a
list, of the wrong rank, and every index out of range or NaN where the kernel reads it as an
index, raises a clear TypeError or ValueError naming the argument, before anything is written:
never a crash, never a read outside an array. Where a variant is a valid array of another
layout (Pinocchio's Fortran-ordered Jacobian), the answer is the contiguous one's."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from sjt_pin import kernels as K


@dataclass
class Arg:
    """An array argument: float64 ('f') or int64 indices ('i'), written or read, of either
    order (Order::any: Pinocchio's matrices) or C order only, whether a list of ints is
    accepted (an index list), None (optional), and whether its length is fixed by the others
    (sized: one entry less does not fit)."""

    kind: str = "f"
    written: bool = False
    any_order: bool = False
    listable: bool = False
    optional: bool = False
    sized: bool = True


@dataclass
class Case:
    """One kernel call: its arguments (by name), which are arrays, and how to call it."""

    call: Any
    args: dict
    arrays: dict = field(default_factory=dict)

    def run(self, **changed):
        return self.call(**{**self.args, **changed})


def _stride12(a: np.ndarray) -> np.ndarray:
    """The numbers of `a` in a view of a byte buffer with 12-byte steps (misaligned and not
    contiguous)."""
    buffer = bytearray(12 * a.size + 16)
    strides = (12,) if a.ndim == 1 else (12 * a.shape[1], 12)
    view = np.ndarray(a.shape, dtype=a.dtype, buffer=buffer, offset=4, strides=strides)
    view[...] = a
    return view


def _strided(a: np.ndarray) -> np.ndarray:
    big = np.repeat(a, 2, axis=-1)
    return big[..., ::2]


def _readonly(a: np.ndarray) -> np.ndarray:
    b = a.copy()
    b.setflags(write=False)
    return b


def _variants(a: np.ndarray, spec: Arg) -> list[tuple[str, object, bool]]:
    """(name, bad value, whether the kernel must accept it as the same array)."""
    with np.errstate(invalid="ignore"):  # (inf and NaN cast to ints: as bad as any)
        as_other = a.astype(np.int64 if spec.kind == "f" else np.int32)
    out = [("strided", _strided(a), False),
           ("stride-12", _stride12(a), False),
           ("byte-swapped", a.astype(a.dtype.newbyteorder(">")), False),
           ("wrong rank", a.reshape(-1)[None] if a.ndim == 1 else a.ravel(), False),
           ("float32" if spec.kind == "f" else "float64",
            a.astype(np.float32 if spec.kind == "f" else np.float64), False),
           ("int64" if spec.kind == "f" else "int32", as_other, False),
           ("a tuple", tuple(map(float, a.ravel())) if spec.kind == "f" else None, False),
           ("None", None, spec.optional)]
    if a.shape[0] > 1:
        out.append(("reversed", a[::-1], False))
    if a.ndim == 2 and min(a.shape) > 1:
        out.append(("Fortran", np.asfortranarray(a), spec.any_order))
    if spec.written:
        out.append(("read-only", _readonly(a), False))
    if spec.kind == "f":
        out.append(("a list", a.tolist(), False))
    return [v for v in out if not (v[0] == "a tuple" and v[1] is None)]


def _snapshot(case: Case) -> dict:
    return {name: np.array(value, copy=True) for name, value in case.args.items()
            if isinstance(value, np.ndarray) and case.arrays.get(name, Arg()).written}


def _check_refused(case: Case, name: str, value, label: str, mention: str | None = None) -> None:
    """A clear refusal naming the argument (or `mention`), nothing written before it."""
    before = _snapshot(case)
    with pytest.raises((TypeError, ValueError)) as caught:
        case.run(**{name: value})
    message = str(caught.value)
    assert (mention or name) in message or "incompatible function arguments" in message, (
        label, message)
    for key, array in before.items():  # nothing written before the refusal
        np.testing.assert_array_equal(case.args[key], array, err_msg=f"{name} {label}: {key}")


def _fresh(case: Case) -> dict:
    return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in case.args.items()}


def _same_answer(case: Case, name: str, value) -> None:
    a, b = _fresh(case), _fresh(case)
    b[name] = value
    ra, rb = case.call(**a), case.call(**b)
    assert (ra is None) == (rb is None) and (ra is None or ra == rb or np.all(ra == rb))
    for key, spec in case.arrays.items():
        if spec.written and isinstance(a[key], np.ndarray):
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}: {key}")


def _fuzz(case: Case) -> int:
    case.run()  # the baseline is valid
    checked = 0
    for name, spec in case.arrays.items():
        base = case.args[name]
        if not isinstance(base, np.ndarray):
            continue
        for label, value, accepted in _variants(base, spec):
            if accepted and value is None:
                case.run(**{name: None})
            elif accepted:
                _same_answer(case, name, value)
            else:
                _check_refused(case, name, value, label)
            checked += 1
        if spec.sized:
            short = base[:-1] if base.ndim == 1 else base[:, :-1]
            _check_refused(case, name, np.ascontiguousarray(short), "too short")
    return checked


# -- the cases -------------------------------------------------------------------------------
RNG = np.random.default_rng(5)


def _pair_rows(k: int, njoints: int) -> np.ndarray:
    rows = np.zeros((k, 13))
    rows[:, 0] = RNG.uniform(0.0, 0.04, k)
    rows[:, 1] = 0.01
    rows[:, 2:4] = RNG.integers(0, njoints, (k, 2))
    n = RNG.normal(size=(k, 3))
    rows[:, 4:7] = n / np.linalg.norm(n, axis=1, keepdims=True)
    rows[:, 7:13] = RNG.normal(size=(k, 6)) * 0.1
    return rows


def damper_case() -> Case:
    k, N, njoints = 3, 4, 3
    return Case(K.damper_rows,
                dict(J=RNG.normal(size=(6, N)), support=np.ones((njoints, N)),
                     pairs=_pair_rows(k, njoints), rate=500.0, A=np.zeros((k, N)),
                     b=np.zeros(k)),
                dict(J=Arg(any_order=True), support=Arg(), pairs=Arg(),
                     A=Arg(written=True), b=Arg(written=True)))


def stoppable_case(jerks: bool = True) -> Case:
    k, N = 3, 4
    return Case(K.stoppable_rows,
                dict(A=RNG.normal(size=(k, N)), b=RNG.uniform(-1, 5, k), dq=RNG.normal(size=N),
                     ddq=RNG.normal(size=N), accelerations=RNG.uniform(5, 10, N),
                     jerks=RNG.uniform(1e3, 5e3, N) if jerks else None, rate=500.0, dt=1e-3,
                     share=0.5, slack=5e-4, reach_accelerations=RNG.uniform(10, 20, N),
                     reach_jerks=RNG.uniform(5e3, 1e4, N) if jerks else None,
                     carried=RNG.uniform(-1, 1, k), speeds=RNG.uniform(0, 3, (2, N)),
                     needs=np.zeros(k)),
                dict(A=Arg(), b=Arg(written=True), dq=Arg(), ddq=Arg(), accelerations=Arg(),
                     jerks=Arg(optional=True), reach_accelerations=Arg(optional=True),
                     reach_jerks=Arg(optional=True), carried=Arg(optional=True),
                     speeds=Arg(optional=True), needs=Arg(written=True, optional=True)))


def stoppable_room_case() -> Case:
    """A user's rows with room (``stoppable_rows`` with ``room``, without the moving
    obstacles' ``carried``, ``speeds`` and ``needs``)."""
    k, N = 3, 4
    return Case(K.stoppable_rows,
                dict(A=RNG.normal(size=(k, N)), b=RNG.uniform(-1, 5, k), dq=RNG.normal(size=N),
                     ddq=RNG.normal(size=N), accelerations=RNG.uniform(5, 10, N),
                     jerks=RNG.uniform(1e3, 5e3, N), rate=1e3, dt=1e-3, share=0.5,
                     slack=5e-4, room=RNG.uniform(-0.01, 0.05, k)),
                dict(A=Arg(), b=Arg(written=True), dq=Arg(), ddq=Arg(), accelerations=Arg(),
                     jerks=Arg(optional=True), room=Arg(optional=True)))


def braking_case() -> Case:
    npairs, N = 3, 4
    return Case(K.braking_reach,
                dict(lever=RNG.uniform(0, 1, (npairs, N)), dq=RNG.normal(size=N),
                     accelerations=RNG.uniform(5, 10, N), jerks=RNG.uniform(1e3, 5e3, N),
                     dt=1e-3, share=0.5, influence=0.05, margin=0.01, out=np.zeros(npairs)),
                dict(lever=Arg(), dq=Arg(), accelerations=Arg(), jerks=Arg(optional=True),
                     out=Arg(written=True)))


def _poses(njoints: int) -> np.ndarray:
    poses = np.tile(np.eye(4), (njoints, 1, 1))
    for j in range(1, njoints):
        q, _ = np.linalg.qr(RNG.normal(size=(3, 3)))
        poses[j, :3, :3] = q * np.sign(np.linalg.det(q))
        poses[j, :3, 3] = RNG.normal(size=3)
    return poses.reshape(njoints, 16)


def witness_case() -> Case:
    njoints, npairs, W = 3, 4, 2
    found = [2, 0]
    rows = np.zeros((len(found) * (1 + W), 13))
    rows[:len(found)] = _pair_rows(len(found), njoints)
    memory = RNG.normal(size=(npairs * W, 6)) * 0.05
    state = np.column_stack([np.full(npairs, float(W)), np.full(npairs, 4.0)])
    return Case(K.witness_rows,
                dict(oMi=None, poses=_poses(njoints), rows=rows, found=np.array(found),
                     memory=memory, state=state, tick=5.0, keep=1.0, apart=1e-4,
                     owners=np.zeros(len(found) * W)),
                dict(poses=Arg(), rows=Arg(written=True),
                     found=Arg("i", listable=True, sized=False),
                     memory=Arg(written=True), state=Arg(written=True),
                     owners=Arg(written=True)))


def _skip_case(prefilter: bool) -> tuple[dict, dict]:
    n, npairs = 3, 4
    ref = RNG.normal(size=n)
    fields = dict(reference=ref, lower=ref - 1.0, upper=ref + 1.0,
                  lever=RNG.uniform(0, 1, (npairs, n)), gap=np.full(npairs, 0.5),
                  near=np.array([0, 2, 3]), floor=RNG.uniform(-0.1, 0.3, npairs),
                  floor_q=ref.copy(), prefilter=np.full(1 + 3 * npairs, -1.0) if prefilter
                  else None)
    specs = dict(reference=Arg(), lower=Arg(), upper=Arg(), lever=Arg(), gap=Arg(),
                 near=Arg("i", listable=True, sized=False), floor=Arg(written=True),
                 floor_q=Arg(written=True), prefilter=Arg(written=True, optional=True))
    return fields, specs


def near_case() -> Case:
    fields, specs = _skip_case(True)
    npairs = fields["lever"].shape[0]
    q = fields["reference"] + 0.01

    def call(q, influence, **skip):
        return K.near_pairs(q, K.Skip(**skip), influence)

    return Case(call, dict(q=q, influence=np.full(npairs, 0.05), **fields),
                dict(q=Arg(), influence=Arg(), **specs))


def refresh_case() -> Case:
    n, npairs = 3, 4
    q = RNG.normal(size=n)
    return Case(K.refresh_pairs,
                dict(q=q, lower=q - 1.0, upper=q + 1.0, gap=RNG.uniform(-0.05, 0.3, npairs),
                     influence=np.full(npairs, 0.05), skin=0.02,
                     floor=RNG.uniform(-0.1, 0.5, npairs), kept=np.array([1, 3]),
                     floor_q=q + 0.01, lever=RNG.uniform(0, 1, (npairs, n))),
                dict(q=Arg(), lower=Arg(), upper=Arg(), gap=Arg(written=True), influence=Arg(),
                     floor=Arg(written=True),
                     kept=Arg("i", listable=True, optional=True, sized=False),
                     floor_q=Arg(written=True, optional=True), lever=Arg()))


def _views(njoints: int, N: int = 4) -> tuple:
    """collision_rows' data views as numpy arrays laid out as Pinocchio's (Fortran)."""
    poses = _poses(njoints).reshape(njoints, 4, 4)
    rotations = [np.asfortranarray(p[:3, :3]) for p in poses]
    translations = [p[:3, 3].copy() for p in poses]
    return (None, np.asfortranarray(RNG.normal(size=(6, N))), rotations, translations)


def sphere_case() -> Case:
    njoints, ngeoms = 3, 4
    centres = np.column_stack([RNG.normal(size=(ngeoms, 3)) * 0.1, np.ones(ngeoms)])
    pairs = np.array([[0, 1], [0, 2], [1, 3]])
    return Case(K.sphere_gaps,
                dict(views=_views(njoints), joints=np.array([0, 1, 2, 2]), centres=centres,
                     pairs=pairs, span=np.full(len(pairs), 0.1), gap=np.zeros(len(pairs))),
                dict(joints=Arg("i"), centres=Arg(), pairs=Arg("i"), span=Arg(),
                     gap=Arg(written=True)))


class _Result:
    """What Pinocchio's computeDistance answers, made up."""

    def __init__(self, d: float, rng: np.random.Generator):
        self.min_distance = d
        n = rng.normal(size=3)
        self.normal = n / np.linalg.norm(n)
        self._p = rng.normal(size=3) * 0.1
        self._q = self._p + self.normal * max(d, 0.0)

    def getNearestPoint1(self):  # noqa: N802 (coal's name)
        return self._p

    def getNearestPoint2(self):  # noqa: N802
        return self._q


def _compute(distances):
    def compute(geometry, geometry_data, k):
        return _Result(float(distances[k]), np.random.default_rng(k))
    return compute


def collision_case(witnesses: bool = True, mimic: bool = True) -> Case:
    njoints, npairs, W, N = 3, 4, 2, 4
    state = np.zeros((npairs, 2))
    state[:, 1] = -np.inf
    fields = dict(floor=np.full(npairs, -np.inf), margins=np.full(npairs, 0.01),
                  joints=np.array([[1, 2], [0, 2], [1, 0], [2, 2]]),
                  rows=np.zeros((npairs * (1 + W), 13)), memory=np.zeros((npairs * W, 6)),
                  state=state, owners=np.zeros(3 * W), support=np.ones((njoints, N)),
                  mimic=RNG.normal(size=(N, 3)) if mimic else None)
    specs = dict(floor=Arg(written=True), margins=Arg(), joints=Arg("i"),
                 rows=Arg(written=True), memory=Arg(written=True), state=Arg(written=True),
                 owners=Arg(written=True), support=Arg(), mimic=Arg(optional=True, sized=False),
                 near=Arg("i", listable=True, sized=False), influence=Arg(),
                 reach=Arg(optional=True))

    def call(near, data, rate, influence, tick, reach, compute, **tables):
        return K.collision_rows(
            K.CollisionTables(geometry=None, geometry_data=None, model=None,
                              update=lambda *args: None, keep=0.02, apart=1e-4,
                              witnesses=witnesses, **tables),
            near, data, rate, influence, tick, reach, compute)

    distances = np.array([0.02, 0.03, 0.2, 0.01])
    return Case(call, dict(near=np.array([0, 1, 3]), data=_views(njoints, N), rate=500.0,
                           influence=np.full(npairs, 0.05), tick=1.0,
                           reach=np.full(npairs, np.inf), compute=_compute(distances),
                           **fields), specs)


CASES = {"damper_rows": damper_case, "stoppable_rows": stoppable_case,
         "stoppable_rows (room)": stoppable_room_case,
         "braking_reach": braking_case, "witness_rows": witness_case, "near_pairs": near_case,
         "refresh_pairs": refresh_case, "sphere_gaps": sphere_case,
         "collision_rows": collision_case}


@pytest.mark.parametrize("name", list(CASES))
def test_every_array_argument_is_checked_before_it_is_read(name):
    case = CASES[name]()
    assert _fuzz(case) >= 6 * len(case.arrays)


# -- indices, counts and numbers the kernels read as such ---------------------------------------
def test_damper_rows_refuse_a_joint_that_is_no_joint():
    case = damper_case()
    for bad in (3.0, -1.0, np.nan, np.inf, 1.5, 1e300):
        pairs = case.args["pairs"].copy()
        pairs[1, 3] = bad
        _check_refused(case, "pairs", pairs, f"joint {bad}")


@pytest.mark.parametrize("name, value", [("rate", np.nan), ("rate", 0.0), ("dt", np.nan),
                                         ("dt", -1e-3), ("share", 1.5), ("share", np.nan),
                                         ("slack", np.nan), ("slack", -1.0)])
def test_stoppable_rows_refuse_numbers_out_of_their_range(name, value):
    case = stoppable_case()
    before = case.args["b"].copy()
    with pytest.raises(ValueError, match=name):
        case.run(**{name: value})
    np.testing.assert_array_equal(case.args["b"], before)


@pytest.mark.parametrize("name, value", [("dt", np.nan), ("dt", 0.0), ("share", 0.0),
                                         ("influence", np.nan), ("margin", np.inf)])
def test_braking_reach_refuses_numbers_out_of_their_range(name, value):
    case = braking_case()
    with pytest.raises(ValueError, match=name):
        case.run(**{name: value})
    assert not case.args["out"].any()


def test_stoppable_rows_and_braking_reach_take_no_jerk_limit():
    stoppable_case(jerks=False).run()
    case = stoppable_case()
    case.run(reach_accelerations=None, reach_jerks=None)
    with pytest.raises(ValueError, match="reach_jerks must hold one number per joint"):
        case.run(reach_accelerations=None, reach_jerks=np.ones(3))
    case = braking_case()
    case.run(jerks=None)


def test_witness_rows_refuse_pairs_joints_and_counts_out_of_range():
    case = witness_case()
    _check_refused(case, "found", [2, 4], "pair beyond the table")
    _check_refused(case, "found", [-1], "negative pair")
    _check_refused(case, "found", [2.0], "a float for a pair")
    _check_refused(case, "found", [2, 0, 1], "more pairs than rows", mention="rows")
    rows = case.args["rows"].copy()
    rows[1, 2] = 3.0  # a joint beyond poses
    _check_refused(case, "rows", rows, "joint beyond the poses")
    rows[1, 2] = np.nan
    _check_refused(case, "rows", rows, "NaN joint")
    for count in (3.0, np.nan, 0.5, np.inf):  # a witness count beyond W = 2, or none
        state = case.args["state"].copy()
        state[2, 0] = count
        _check_refused(case, "state", state, f"count {count}")
    memory = np.zeros((7, 6))  # not npairs W rows
    _check_refused(case, "memory", memory, "memory of 7 rows for 4 pairs")
    # the poses read from data.oMi are written into poses: a read-only poses is refused
    case.args["oMi"] = [np.eye(4)] * 3
    with pytest.raises(ValueError, match="poses must be writable"):
        case.run(poses=_readonly(case.args["poses"]))


def test_near_and_refresh_pairs_refuse_pairs_out_of_range():
    near = near_case()
    for bad in ([0, 4], [-1], np.array([0, 9]), [1.0]):
        _check_refused(near, "near", bad, f"near {bad}")
    refresh = refresh_case()
    for bad in ([4], [-2], np.array([1, 99]), ["1"]):
        _check_refused(refresh, "kept", bad, f"kept {bad}")
    _check_refused(refresh, "floor_q", refresh.args["floor_q"][:2].copy(), "floor_q short")
    refresh.run(kept=None, floor_q=None)  # (neither: none kept, not yet aged)


def test_sphere_gaps_refuse_joints_geometries_and_views_that_do_not_fit():
    case = sphere_case()
    _check_refused(case, "joints", np.array([0, 1, 3, 2]), "joint beyond the views")
    _check_refused(case, "joints", np.array([0, -1, 2, 2]), "negative joint")
    _check_refused(case, "pairs", np.array([[0, 1], [0, 4], [1, 3]]), "geometry beyond")
    views = case.args["views"]
    for bad in ((views[0], views[1], views[2][:2], views[3][:2]),  # fewer joints
                (views[0], views[1], views[2][:2], views[3]),  # lists of other lengths
                (views[0], views[1], tuple(views[2]), views[3]),  # not lists
                views[:3],
                (views[0], views[1], [r.astype(np.float32) for r in views[2]], views[3]),
                (views[0], views[1], views[2], [t[:2].copy() for t in views[3]]),
                (views[0], views[1], [_stride12(r) for r in views[2]], views[3])):
        with pytest.raises((TypeError, ValueError)):
            case.run(views=bad)
    # a rotation in C order is the same rotation (Pinocchio's are Fortran-ordered)
    _same_answer(case, "views", (views[0], views[1], [np.ascontiguousarray(r) for r in views[2]],
                                 views[3]))


@pytest.mark.parametrize("witnesses", [False, True])
def test_collision_rows_refuse_tables_that_do_not_fit(witnesses):
    case = collision_case(witnesses=witnesses)
    out = case.run()
    assert out is not None and out[2] is not None and out[4] >= 0
    for bad in ([0, 4], [-1], [3] * 13):
        _check_refused(collision_case(witnesses=witnesses), "near", bad, f"near {bad}")
    case = collision_case(witnesses=witnesses)
    _check_refused(case, "joints", np.array([[1, 2], [0, 3], [1, 0], [2, 2]]), "joint 3")
    _check_refused(case, "mimic", np.zeros((3, 3)), "mimic of 3 rows for N = 4")
    views = case.args["data"]
    _check_refused(case, "data", (views[0], views[1][:, :3].copy(), views[2], views[3]),
                   "J of 3 columns for N = 4", mention="J")
    with pytest.raises(ValueError, match="views"):
        case.run(data=(views[0], views[1], views[2][:2], views[3][:2]))
    if witnesses:
        state = case.args["state"].copy()
        state[1, 0] = 5.0  # more witnesses than W = 2
        _check_refused(case, "state", state, "count 5")


def test_collision_rows_read_what_coal_answers_as_numbers_or_refuse_it():
    case = collision_case()

    class Odd(_Result):
        def getNearestPoint1(self):  # noqa: N802
            return np.zeros(2)

    with pytest.raises(ValueError, match="nearest point 1"):
        case.run(compute=lambda g, d, k: Odd(0.02, np.random.default_rng(k)))

    class Text(_Result):
        def __init__(self, rng):
            super().__init__(0.02, rng)
            self.min_distance = "near"

    with pytest.raises(TypeError, match="min_distance"):
        case.run(compute=lambda g, d, k: Text(np.random.default_rng(k)))


def test_index_arrays_are_read_in_place_only_as_int64():
    case = refresh_case()
    for bad in (np.array([1, 3], dtype=np.int32), np.array([1.0, 3.0]), np.array([[1, 3]]),
                _stride12(np.array([1.0, 3.0])).astype(np.int64)[::-1]):
        _check_refused(case, "kept", bad, f"kept {bad.dtype} {bad.shape}")
