"""The boundary of the search's and the tasks' compiled entries (the module _core: src/search.cpp,
search_pose.cpp, lie.cpp, symmetric_eigen.cpp, transforms.cpp) and of bounds.cpp's
least_widening: every array argument in every layout, dtype and length the kernels do not read
(strided, reversed, a stride-12 view of a byte buffer, unaligned, Fortran-ordered, short,
read-only where written, of another dtype or rank, indices out of range) raises TypeError or
ValueError naming the argument, before anything is read; NaN is refused where it would index or
weigh, and elsewhere flows into the result. Run under AddressSanitizer (the CI's sanitizer job)
these calls also show that nothing is read outside an array."""

import numpy as np
import pinocchio as pin
import pytest

from sjt_pin import kernels as K

N, NQ = 3, 4  # three joints: two of one coordinate, a continuous joint's (cos, sin) pair
RNG = np.random.default_rng(7)
J_POSE = RNG.normal(size=(6, N))


def _search(m=6, **options):
    """A SetPointSearch of m rows on the three joints, joints 0 and 1 limited."""
    return K.SetPointSearch(np.ones(m), np.ones(N), NQ, np.array([0, 1]), np.array([0, 1]),
                            np.array([-1.0, -2.0]), np.array([1.0, 2.0]), damping=1e-6,
                            column_tol=1e-10, length=0.1, scaled=True, **options)


def _pose_arguments():
    return {"rotation_t": np.eye(3), "translation": np.zeros(3),
            "target": pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.1])), np.array([0.1, 0.2, 0.3])).np,
            "joints": np.array([[0, 1, 2], [0, 1, 2], [0, 0, 1]]),
            "trial": np.array([0.1, 0.2, 1.0, 0.0]), "error": np.zeros(6)}


def _search_pose(args):
    return K.search_pose(args["search"], args["jacobian"], (), args["rotation_t"],
                         args["translation"], args["target"], args["joints"], args["trial"],
                         args["error"], 3)


def _search_table(args):
    return K.search_table(args["search"], args["jacobian"], (), args["rotation_t"],
                          args["translation"], args["target"], args["joints"], args["trial"],
                          args["error"], 6, args["configurations"], args["distance"],
                          args["best_q"], 3, 2, np.inf)


def _new_search(args):
    return K.SetPointSearch(args["sqrt_weight"], args["mask"], NQ, args["limit_q"],
                            args["limit_v"], args["lower"], args["upper"], damping=1e-6,
                            column_tol=1e-10)


# each entry: (valid arguments, the call, the arguments it writes, those whose length the others
# fix, the index tables and their ranges' bad values, the float arguments it refuses NaN in)
ENTRIES = {
    "jlog6_inverse": (
        lambda: {"xi": RNG.normal(size=6), "out": np.zeros((6, 6))},
        lambda a: K.jlog6_inverse(a["xi"], a["out"]), {"out"}, {"xi", "out"}, {}, set()),
    "symmetric_eigen": (
        lambda: {"H": RNG.normal(size=(N, N)), "values": np.zeros(N), "vectors": np.zeros((N, N))},
        lambda a: K.symmetric_eigen(a["H"], a["values"], a["vectors"]), {"values", "vectors"},
        {"H", "values", "vectors"}, {}, {"H"}),
    "least_widening": (
        lambda: {"cap_lo": -np.ones(N), "cap_hi": np.ones(N), "hard_lo": np.full(N, -5.0),
                 "hard_hi": np.full(N, 5.0), "a": RNG.normal(size=N)},
        lambda a: K.least_widening(a["cap_lo"], a["cap_hi"], a["hard_lo"], a["hard_hi"], a["a"],
                                   -3.0),
        set(), {"cap_lo", "cap_hi", "hard_lo", "hard_hi"}, {},
        {"cap_lo", "cap_hi", "hard_lo", "hard_hi", "a"}),
    "frame_velocity": (
        lambda: {"oMf": pin.SE3.Random().np, "oMd": pin.SE3.Random().np,
                 "velocity": RNG.normal(size=6), "out": np.zeros(6)},
        lambda a: K.frame_velocity(a["oMf"], a["oMd"], a["velocity"], a["out"]), {"out"},
        {"oMf", "oMd", "velocity", "out"}, {}, set()),
    "rotation_defect": (
        lambda: {"M": pin.SE3.Random().np}, lambda a: K.rotation_defect(a["M"]), set(), {"M"},
        {}, set()),
    "position_rows": (
        lambda: {"J6": RNG.normal(size=(6, N)), "oMf": pin.SE3.Random().np,
                 "p_d": RNG.normal(size=3), "velocity": RNG.normal(size=6),
                 "axes": np.array([2, 0]), "J": np.zeros((2, N)), "e": np.zeros(2),
                 "ff": np.zeros(2)},
        lambda a: K.position_rows(a["J6"], a["oMf"], a["p_d"], a["velocity"], a["axes"], a["J"],
                                  a["e"], a["ff"]),
        {"J", "e", "ff"}, {"J6", "oMf", "p_d", "velocity", "J", "e", "ff"},
        {"axes": [np.array([3, 0]), np.array([-1, 0]), np.array([0, 1, 2, 0])]}, set()),
    "unit_defect": (
        lambda: {"q": RNG.normal(size=8), "blocks": np.array([[0, 4], [6, 2]])},
        lambda a: K.unit_defect(a["q"], a["blocks"]), set(), set(),
        {"blocks": [np.array([[5, 4]]), np.array([[-1, 2]]), np.array([[0, -1]]),
                    np.array([[2**62, 2**62]]), np.array([[0, 9]])]}, set()),
    "SetPointSearch": (
        lambda: {"sqrt_weight": np.ones(6), "mask": np.ones(N), "limit_q": np.array([0, 2]),
                 "limit_v": np.array([0, 2]), "lower": np.array([-1.0, -2.0]),
                 "upper": np.array([1.0, 2.0])},
        _new_search, set(), {"limit_v", "lower", "upper"},
        {"limit_q": [np.array([0, NQ]), np.array([-1, 0])],
         "limit_v": [np.array([0, N]), np.array([0, -3])]},
        {"sqrt_weight", "mask", "lower", "upper"}),
    "SetPointSearch.iterate": (
        lambda: {"search": _search(), "J": RNG.normal(size=(6, N)), "e": RNG.normal(size=6),
                 "q": np.array([0.1, 0.2, 1.0, 0.0])},
        lambda a: a["search"].iterate(a["J"], a["e"], a["q"]), set(), {"J", "e", "q"}, {},
        set()),
    "search_pose": (
        lambda: {"search": _search(), "jacobian": lambda: J_POSE, **_pose_arguments()},
        _search_pose, {"trial", "error"}, {"rotation_t", "translation", "target", "trial",
                                            "error"},
        {"joints": [np.array([[0, 1, 3], [0, 1, 2], [0, 0, 1]]),  # a pair past q's end
                    np.array([[0, 1, 2], [0, 1, 3], [0, 0, 1]]),  # a v index past n
                    np.array([[0, 1, 2], [0, 1, 2], [0, 0, 2]]),  # no such kind
                    np.array([[-1, 1, 2], [0, 1, 2], [0, 0, 1]]),
                    np.array([[0, 1], [0, 1]])]}, set()),
    "search_table": (
        lambda: {"search": _search(), "jacobian": lambda: J_POSE, **_pose_arguments(),
                 "configurations": RNG.normal(size=(5, NQ)), "distance": RNG.random(5),
                 "best_q": np.zeros(NQ)},
        _search_table, {"trial", "error", "distance", "best_q"},
        {"rotation_t", "translation", "target", "trial", "error", "configurations", "distance",
         "best_q"}, {}, set()),
}


def _stride_12(a: np.ndarray) -> np.ndarray:
    """``a``'s shape read through a stride of 12 bytes from a byte buffer (overlapping,
    unaligned numbers)."""
    raw = np.zeros(12 * max(a.size, 1) + 8, dtype=np.uint8)
    strides = (12,) if a.ndim == 1 else (12 * a.shape[1], 12)
    return np.ndarray(a.shape, dtype=a.dtype, buffer=raw, offset=1, strides=strides)


def _unaligned(a: np.ndarray) -> np.ndarray:
    raw = np.zeros(a.nbytes + 8, dtype=np.uint8)
    return np.frombuffer(raw.data, dtype=a.dtype, count=a.size, offset=3).reshape(a.shape)


def bad_layouts(a: np.ndarray) -> list[tuple[str, object]]:
    """``a``'s values (or its shape) in layouts the kernels refuse: every one of them not a
    C-contiguous, aligned array (those that happen to be one, of one entry, are left out)."""
    views = []
    if a.ndim == 1:
        views.append(("strided", np.repeat(a, 2)[::2]))
        views.append(("reversed", a[::-1]))
    else:
        views.append(("strided", np.repeat(a, 2, axis=1)[:, ::2]))
        views.append(("reversed", a[::-1, ::-1]))
        views.append(("fortran", np.asfortranarray(a)))
    views.append(("stride-12", _stride_12(a)))
    views.append(("unaligned", _unaligned(a)))
    return [(label, v) for label, v in views
            if not (v.flags.c_contiguous and v.flags.aligned)]


def bad_types(a: np.ndarray) -> list[tuple[str, object]]:
    """``a`` as another dtype, byte order, rank or type."""
    floating = a.dtype == np.float64
    out = [("list", a.tolist()), ("0-d", np.array(1.0 if floating else 1)),
           ("rank+1", a[None]), ("None", None)]
    if floating:
        out += [("float32", a.astype(np.float32)), ("int64", a.astype(np.int64)),
                ("big-endian", a.astype(">f8")), ("complex", a.astype(complex))]
    else:
        out += [("float64", a.astype(float)), ("int32", a.astype(np.int32)),
                ("big-endian", a.astype(">i8")), ("uint64", a.astype(np.uint64))]
    return out


def _arrays(entry):
    make = ENTRIES[entry][0]
    return [k for k, v in make().items() if isinstance(v, np.ndarray)]


CASES = [(entry, name) for entry in ENTRIES for name in _arrays(entry)]


@pytest.mark.parametrize("entry, name", CASES)
def test_every_layout_and_dtype_the_kernels_do_not_read_is_refused(entry, name):
    make, call, written, sized, _, _ = ENTRIES[entry]
    call(make())  # the valid arguments pass
    valid = make()[name]
    for label, bad in bad_layouts(valid) + bad_types(valid):
        args = make()
        args[name] = bad
        with pytest.raises(TypeError) as info:
            call(args)
        assert str(info.value).startswith(f"{name} must be"), (label, str(info.value))


@pytest.mark.parametrize("entry, name", [(e, n) for e, n in CASES if n in ENTRIES[e][2]])
def test_a_read_only_output_is_refused(entry, name):
    make, call = ENTRIES[entry][:2]
    args = make()
    args[name].flags.writeable = False
    with pytest.raises(ValueError, match=f"{name} must be writable"):
        call(args)


@pytest.mark.parametrize("entry, name", [(e, n) for e, n in CASES if n in ENTRIES[e][3]])
def test_a_short_or_long_array_is_refused(entry, name):
    make, call = ENTRIES[entry][:2]
    valid = make()[name]
    variants = [valid[:-1], np.concatenate([valid, valid[:1]])]
    if valid.ndim == 2:
        variants += [np.ascontiguousarray(valid[:, :-1])]
    for bad in variants:
        args = make()
        args[name] = np.ascontiguousarray(bad)
        with pytest.raises(ValueError) as info:
            call(args)
        # (J6's columns are the joints: the rows written for them no longer fit)
        assert name in str(info.value) or name == "J6", str(info.value)


@pytest.mark.parametrize("entry, name", [(e, n) for e in ENTRIES for n in ENTRIES[e][4]])
def test_indices_out_of_range_are_refused(entry, name):
    make, call = ENTRIES[entry][:2]
    for bad in ENTRIES[entry][4][name]:
        args = make()
        args[name] = bad
        with pytest.raises(ValueError, match=name.split("_")[0]):
            call(args)


@pytest.mark.parametrize("entry, name", CASES)
def test_nan_is_refused_where_it_would_weigh_and_flows_elsewhere(entry, name):
    make, call, _, _, tables, refused = ENTRIES[entry]
    args = make()
    if args[name].dtype != np.float64 or not args[name].size:
        return
    args[name] = args[name].copy()
    args[name].flat[0] = np.nan
    if name in refused:
        with pytest.raises(ValueError, match=f"{name} contains"):
            call(args)
    else:
        call(args)  # (a NaN result, or a search that stalls on it: never a crash)


def test_a_jacobian_the_kernel_does_not_read_is_refused():
    """search_pose's callable returns the frame's rows: in any other layout, shape or type
    than (6, n) float64 C-contiguous they are refused, and its own exception propagates."""
    make, call = ENTRIES["search_pose"][:2]
    for _, bad in bad_layouts(J_POSE) + bad_types(J_POSE) + [
            ("short", np.zeros((5, N))), ("wide", np.zeros((6, N + 1)))]:
        args = make()
        args["jacobian"] = lambda bad=bad: bad
        with pytest.raises((TypeError, ValueError), match="the Jacobian"):
            call(args)

    def broken():
        raise RuntimeError("no kinematics")

    args = make()
    args["jacobian"] = broken
    with pytest.raises(RuntimeError, match="no kinematics"):
        call(args)
    with pytest.raises(TypeError, match="callable"):
        K.search_pose(_search(), None, (), *list(_pose_arguments().values()), 3)
    with pytest.raises(ValueError, match="6 rows"):
        K.search_pose(_search(m=3), lambda: J_POSE, (), *list(_pose_arguments().values()), 3)


def test_the_search_refuses_parameters_it_cannot_use():
    none = np.zeros(0, dtype=np.int64)
    for options, message in (({"damping": np.nan}, "damping"), ({"column_tol": -1.0}, "column"),
                             ({"length": np.inf}, "length"), ({"identity_rows": 2}, "identity")):
        kwargs = {"damping": 1e-6, "column_tol": 0.0, **options}
        with pytest.raises(ValueError, match=message):
            K.SetPointSearch(np.ones(6), np.ones(N), NQ, none, none, np.zeros(0), np.zeros(0),
                             **kwargs)
    with pytest.raises(ValueError, match="at least one row"):
        K.SetPointSearch(np.ones(0), np.ones(N), NQ, none, none, np.zeros(0), np.zeros(0),
                         damping=1e-6, column_tol=0.0)


def test_the_search_s_arrays_are_its_own_views():
    """J, e and q are read-only views of the search's current point, step a writable one; they
    keep the search alive, and the search never reallocates them."""
    search = _search()
    J, e, q, step = search.J, search.e, search.q, search.step
    assert J.shape == (6, N) and e.shape == (6,) and q.shape == (NQ,) and step.shape == (N,)
    for view in (J, e, q):
        assert not view.flags.writeable
        with pytest.raises(ValueError):
            view[0] = 1.0
    assert step.flags.writeable and step.flags.c_contiguous
    search.tol, search.error_rows = 1e-12, 6
    assert search.iterate(J_POSE * 0 + 1.0, np.full(6, 0.5), np.array([0.1, 0.2, 1.0, 0.0])) == 0
    np.testing.assert_array_equal(search.q, [0.1, 0.2, 1.0, 0.0])
    assert np.shares_memory(q, search.q) and np.all(step == search.step)
    del search
    assert q[2] == 1.0  # the view holds the search
