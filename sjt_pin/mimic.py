"""Mimic joints: a URDF ``<mimic joint="p" multiplier="k" offset="o"/>`` on joint ``m`` means
``q_m = k q_p + o`` (rad or m) at all times — a gripper's second finger, a parallel linkage.

Such a joint is not a coordinate of its own. :func:`read_mimics` reads and checks the relations
of a URDF, and :func:`apply_mimics` turns each mimicking joint of a Pinocchio model into one of
Pinocchio's mimic joints (``pinocchio.transformJointIntoMimic``): it leaves ``q`` and ``q_dot``
(``nq``, ``nv`` shrink by one per mimic joint), its Jacobian column is added, times ``k``, to
the column of the joint it follows, and every kinematic result — ``fk``, the Jacobians, the
solvers' steps, the viewer's meshes — keeps the relation exactly. The solvers therefore move
only the independent coordinates.

Mimic chains (``c`` follows ``b``, which follows ``a``) are composed into one relation on the
joint at the chain's root. Pinocchio needs the independent joint of a group to come first in
its joint order; when the URDF's tree puts a mimicking joint first, that one becomes the
independent coordinate and the relation is inverted (it is the same relation). The limits of
a mimicking joint hold through its relation: they narrow the position range and the speed
limit of the joint it follows (see :func:`apply_mimics`).
"""

from __future__ import annotations

import difflib
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .exceptions import URDFError
from .joint_ranges import NO_LIMIT, position_ranges

#: joint types that may mimic or be mimicked (1-DoF joints)
MIMIC_TYPES = ("revolute", "prismatic", "continuous")


@dataclass(frozen=True)
class MimicJoint:
    """One mimic relation ``q[joint] = multiplier * q[mimicked] + offset`` (rad or m)."""

    joint: str  #: the mimicking joint (no coordinate of its own)
    mimicked: str  #: the joint it follows (an independent coordinate after apply_mimics)
    multiplier: float
    offset: float  #: rad or m
    #: the mimicking joint's own position range (rad or m) from its URDF ``<limit>``, as
    #: :func:`apply_mimics` applied the relation (``-inf``/``inf``: none, or not yet read)
    lower: float = -math.inf
    upper: float = math.inf


def read_mimics(joints: Sequence, error: Callable[[str], URDFError]) -> list[MimicJoint]:
    """The ``<mimic>`` relations of a URDF's ``<joint>`` elements (lxml), as written.

    ``error`` turns a problem into the :class:`URDFError` to raise. Refused: a ``<mimic>``
    without ``joint=``, naming its own joint, on a planar or floating joint or naming a joint
    that is not revolute, prismatic or continuous, a continuous joint mimicking a revolute or
    prismatic one (or the reverse: an angle on the circle has no linear relation to a
    coordinate), a multiplier or offset that is not a finite number, a zero multiplier (a
    locked joint: write ``lower == upper``), two ``<mimic>`` in one joint, and a cycle of mimic
    joints. Passed over, as Pinocchio and ROS do: a ``<mimic>`` on a fixed joint (it stays
    fixed; "reduced" models weld joints and keep the tag), and, with a ``UserWarning``, one
    naming a joint that does not exist (the joint then moves on its own).
    """
    kinds = {j.get("name"): j.get("type") for j in joints}
    mimics: list[MimicJoint] = []
    for joint in joints:
        tags = [e for e in joint if isinstance(e.tag, str) and e.tag == "mimic"]
        if not tags:
            continue
        name, kind = joint.get("name"), joint.get("type")
        if kind == "fixed":
            continue
        what = f"joint {name!r}: <mimic>"
        if len(tags) > 1:
            raise error(f"{what} appears {len(tags)} times; a joint follows one joint")
        tag = tags[0]
        target = tag.get("joint")
        if not target:
            raise error(f'{what} has no joint="..." naming the joint it follows')
        if target == name:
            raise error(f"{what} names its own joint")
        if target not in kinds:
            close = difflib.get_close_matches(target, kinds, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            warnings.warn(f"URDF joint {name!r}: <mimic> names joint {target!r}, "
                          f"which is not defined{hint}; {name!r} moves on its own",
                          UserWarning, stacklevel=4)
            continue
        for who, its_kind in ((name, kind), (target, kinds[target])):
            if its_kind not in MIMIC_TYPES:
                raise error(f"{what}: joint {who!r} is {its_kind}; mimic relations join "
                            f"{', '.join(MIMIC_TYPES)} joints")
        if (kind == "continuous") != (kinds[target] == "continuous"):
            raise error(f"{what}: a {kind} joint cannot follow the {kinds[target]} joint "
                        f"{target!r} (continuous joints mimic continuous joints only)")
        multiplier = _number(tag, "multiplier", 1.0, what, error)
        offset = _number(tag, "offset", 0.0, what, error)
        if multiplier == 0.0:
            raise error(f"{what} has multiplier 0, which locks the joint at its offset; write "
                        "<limit lower upper> with lower == upper for a locked joint")
        mimics.append(MimicJoint(name, target, multiplier, offset))
    resolved(mimics, error)  # refuse cycles here, with the URDF's names
    return mimics


def _number(tag, attribute: str, default: float, what: str,
            error: Callable[[str], URDFError]) -> float:
    text = tag.get(attribute)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise error(f"{what} {attribute}={text!r} is not a finite number")
    return value


def resolved(mimics: Sequence[MimicJoint],
             error: Callable[[str], URDFError]) -> dict[str, tuple[str, float, float]]:
    """Every mimicking joint as ``(root, a, b)`` with ``q = a q_root + b``: the chains composed
    down to a joint that follows no other. A cycle is an error."""
    follows = {m.joint: m for m in mimics}
    out: dict[str, tuple[str, float, float]] = {}
    for m in mimics:
        a, b, seen, at = 1.0, 0.0, [m.joint], m
        while True:  # q = a q_at.joint + b, with q_at.joint = k q_at.mimicked + o
            a, b = a * at.multiplier, a * at.offset + b
            if at.mimicked not in follows:
                break
            if at.mimicked in seen:
                cycle = " -> ".join(map(repr, [*seen[seen.index(at.mimicked):], at.mimicked]))
                raise error(f"the mimic joints {cycle} follow each other in a cycle")
            seen.append(at.mimicked)
            at = follows[at.mimicked]
        if not (math.isfinite(a) and math.isfinite(b)) or a == 0.0:
            raise error(f"joint {m.joint!r}: its chain of <mimic> relations composes to "
                        f"q = {a:g} q[{at.mimicked!r}] + {b:g}, not a usable relation")
        out[m.joint] = (at.mimicked, a, b)
    return out


def apply_mimics(model: pin.Model, mimics: Sequence[MimicJoint],
                 error: Callable[[str], URDFError]) -> tuple[pin.Model, list[MimicJoint]]:
    """``model`` with every mimicking joint turned into a Pinocchio mimic joint, and the
    relations as applied (each on an independent joint of the new model).

    In each group of joints tied by relations, the one first in Pinocchio's joint order is the
    independent coordinate. The other members' position limits narrow its range through their
    relations (``lower_m <= a q + b <= upper_m``), and their speed limits its speed limit
    (``|a| |q_dot| <= v_m``); an empty range is an error naming the joints.
    """
    if not mimics:
        return model, []
    roots = resolved(mimics, error)
    index = {name: model.getJointId(name) for name in {*roots, *(r[0] for r in roots.values())}}
    missing = [name for name, j in index.items() if j >= model.njoints]
    if missing:
        raise error(f"mimic joints {sorted(missing)} are not joints of the model")
    lower, upper = position_ranges(model)
    speed = np.asarray(model.velocityLimit, dtype=float).copy()
    groups: dict[str, list[tuple[str, float, float]]] = {}
    for name, (root, a, b) in roots.items():
        groups.setdefault(root, [(root, 1.0, 0.0)]).append((name, a, b))
    applied: list[tuple[int, int, MimicJoint]] = []
    bounds: dict[int, list] = {}
    for members in groups.values():
        first, relations, bound = _tie(model, members, index, (lower, upper, speed), error)
        applied += relations
        bounds[first] = bound
    for leader, follower, mimic in sorted(applied, key=lambda x: x[1]):
        model = pin.transformJointIntoMimic(model, leader, follower, mimic.multiplier,
                                           mimic.offset)
    for j, (lo, hi, v_max) in bounds.items():
        joint = model.joints[j]
        if np.isfinite(lo) and np.isfinite(hi):
            model.lowerPositionLimit[joint.idx_q] = lo
            model.upperPositionLimit[joint.idx_q] = hi
        if math.isfinite(v_max):
            model.velocityLimit[joint.idx_v] = v_max
    return model, [m for _, _, m in sorted(applied, key=lambda x: x[1])]


def _tie(model: pin.Model, members: list[tuple[str, float, float]], index: dict[str, int],
         limits: tuple[np.ndarray, np.ndarray, np.ndarray], error: Callable[[str], URDFError]
         ) -> tuple[int, list[tuple[int, int, MimicJoint]], list[float]]:
    """One group of joints tied by relations ``q_x = a_x q_root + b_x`` (``members``): the
    joint first in the model's order becomes independent. Returns its id, each other member's
    ``(leader id, follower id, relation on the independent joint)``, and the independent joint's
    ``[lower, upper, speed]`` narrowed by the members' own position and speed limits."""
    lower, upper, speed = limits
    first, a0, b0 = min(members, key=lambda m: index[m[0]])
    joint = model.joints[index[first]]
    lo, hi = lower[joint.idx_q], upper[joint.idx_q]
    v_max = speed[joint.idx_v] if 0.0 < speed[joint.idx_v] < NO_LIMIT else math.inf
    applied = []
    for name, a_x, b_x in members:
        if name == first:
            continue
        k = a_x / a0  # q_x = k q_first + o
        o = b_x - k * b0
        own = model.joints[index[name]]
        own_range = ((float(lower[own.idx_q]), float(upper[own.idx_q])) if own.nq == 1
                     else (-math.inf, math.inf))
        applied.append((index[first], index[name], MimicJoint(name, first, k, o, *own_range)))
        if own.nq == 1 and np.isfinite(lower[own.idx_q]):
            ends = sorted(((lower[own.idx_q] - o) / k, (upper[own.idx_q] - o) / k))
            lo, hi = max(lo, ends[0]), min(hi, ends[1])
            if lo > hi + 1e-12 * max(1.0, abs(lo)):
                raise error(f"joint {name!r} mimics {first!r} as q = {k:g} q[{first!r}] "
                            f"{o:+g}, but no value of {first!r} keeps both within their "
                            "position limits")
            hi = max(lo, hi)
        own_speed = speed[own.idx_v]
        if 0.0 < own_speed < NO_LIMIT:
            v_max = min(v_max, own_speed / abs(k))
    return index[first], applied, [lo, hi, v_max]


def reduced_configuration(full: pin.Model, model: pin.Model, q: np.ndarray) -> np.ndarray:
    """A configuration ``q`` of ``full`` (every joint its own coordinates) on ``model`` (the
    same joints, some of them mimic joints): the mimic joints' coordinates dropped."""
    out = np.empty(model.nq)
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq:
            source = full.joints[j]
            out[joint.idx_q:joint.idx_q + joint.nq] = q[source.idx_q:source.idx_q + source.nq]
    return out


def joint_values(model: pin.Model, mimics: Sequence[MimicJoint], q: np.ndarray
                 ) -> dict[str, float]:
    """The position (rad or m) of every 1-DoF joint at ``q``, mimic joints included, by name
    (a continuous joint's angle from its (cos, sin)): what a robot's joint controllers take."""
    values: dict[str, float] = {}
    for j in range(1, model.njoints):
        joint = model.joints[j]
        if joint.nq == 1 and joint.nv == 1:
            values[model.names[j]] = float(q[joint.idx_q])
        elif joint.nq == 2 and joint.nv == 1:
            values[model.names[j]] = math.atan2(q[joint.idx_q + 1], q[joint.idx_q])
    for m in mimics:
        values[m.joint] = m.multiplier * values[m.mimicked] + m.offset
    return values
