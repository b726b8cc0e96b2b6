"""URDF input checked before Pinocchio parses it, so that a bad one gets an error saying why.

Pinocchio's URDF parser (urdfdom) answers every broken file with "The XML stream does not
contain a valid URDF model." and prints the reason to stderr; it also accepts some broken robots
silently (a zero-length joint axis, lower > upper limits, a cycle cut off from the root). Here
:func:`read_urdf` turns ``Robot.from_urdf``'s argument into a :class:`URDFSource`
(:mod:`sjt_pin.urdf_source`), :func:`check_urdf` rejects what is not a URDF tree with sane
numbers, and :func:`build_model` runs Pinocchio and puts whatever it prints to stderr into the
error (:mod:`sjt_pin.urdf_build`). Every error is a :class:`URDFError` whose message starts
with the file (or ``<URDF string>``) and names the offending joint or link.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from lxml import etree

from .exceptions import URDFError  # noqa: F401 (the docstrings' URDFError)
from .mimic import MimicJoint, apply_mimics, read_mimics
from .planar import orient_planar_joints
from .urdf_build import build_model, captured_stderr  # noqa: F401 (re-exported: the old path)
from .urdf_source import (  # noqa: F401 (STRING_LABEL, read_urdf re-exported: the old path)
    STRING_LABEL,
    URDFSource,
    preview,
    read_urdf,
    starts_xml,
)
from .validation import name_list

#: An ``<axis xyz>`` shorter than this (it is normalised) is refused: no CAD tool means a
#: direction by a vector of norm 1e-9, and below ~1e-154 its norm cannot even be computed.
AXIS_EPSILON = 1e-9
#: The deepest tree accepted, in links from the root: Pinocchio's parser recurses once per link
#: and overflows an 8 MB stack (a SIGSEGV, no message) between 3,750 and 3,800 (measured).
MAX_DEPTH = 1000
#: The joint types of the URDF specification.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
#: Joint types whose ``<axis>`` matters (for ``planar`` it is the plane's normal).
_AXIS_TYPES = {"revolute", "continuous", "prismatic", "planar"}
#: Joint types whose ``<limit lower upper>`` bound the position.
_LIMITED_TYPES = {"revolute", "prismatic"}


@dataclass
class URDFContent:
    """What :func:`check_urdf` found that Pinocchio's parser does not keep by itself."""

    #: the ``<mimic>`` relations (:func:`sjt_pin.mimic.read_mimics`)
    mimics: list[MimicJoint] = field(default_factory=list)
    #: planar joint -> the unit normal of its plane (its ``<axis>``), where it is not +z
    planar_normals: dict[str, np.ndarray] = field(default_factory=dict)


def load_model(source: URDFSource, content: URDFContent | None = None
               ) -> tuple[pin.Model, list[MimicJoint], pin.Model]:
    """Pinocchio's model of ``source``, checked (:func:`check_urdf`, unless its ``content``
    is given), with its planar joints in the planes of their axes (:mod:`sjt_pin.planar`) and
    its mimic joints as Pinocchio mimic joints (:mod:`sjt_pin.mimic`); the mimic relations
    applied; and the model before them (every joint a coordinate of its own)."""
    if content is None:
        content = check_urdf(source)
    unmimicked = orient_planar_joints(build_model(source), content.planar_normals)
    model, mimics = apply_mimics(unmimicked, content.mimics, source.error)
    return model, mimics, unmimicked


# -- the document ------------------------------------------------------------------------------
def check_urdf(source: URDFSource) -> URDFContent:
    """Raise :class:`URDFError` unless ``source`` is well-formed XML describing one tree of
    named links joined by URDF joints, at most :data:`MAX_DEPTH` links deep, with finite
    origins and axes, axes of norm at least :data:`AXIS_EPSILON`, ``lower <= upper`` limits
    and mimic relations Pinocchio can keep. Returns what Pinocchio's parser would drop: the
    mimic relations and the planes of planar joints."""
    root = _parse(source)
    if _tag(root) != "robot":
        raise source.error(f"the root element is <{_tag(root)}>, not <robot>")
    links = _children(root, "link")
    joints = _children(root, "joint")
    link_names = _names(links, "link", source)
    _names(joints, "joint", source)
    if not links:
        raise source.error("<robot> has no <link>")
    for link in links:
        _check_link(link, source)
    parents: dict = {}  # child link -> its joint element
    known_links = set(link_names)  # once: the checks stay linear in the URDF's size
    for joint in joints:
        _check_joint(joint, known_links, source)
        child = _link_of(joint, "child")
        if child in parents:
            raise source.error(
                f"link {child!r} has two parents: joint {parents[child].get('name')!r} (from "
                f"link {_link_of(parents[child], 'parent')!r}) and joint "
                f"{joint.get('name')!r} (from link {_link_of(joint, 'parent')!r})")
        parents[child] = joint
    _check_tree(link_names, parents, source)
    _check_depth(link_names, parents, source)
    content = URDFContent(read_mimics(joints, source.error))
    for joint in joints:
        if joint.get("type") == "planar":
            axes = _children(joint, "axis")
            xyz = _vector(axes[0], "xyz", "", source) if axes else None
            normal = np.array((1.0, 0.0, 0.0) if xyz is None else xyz)  # the URDF default
            normal /= np.linalg.norm(normal)
            if not np.array_equal(normal, [0.0, 0.0, 1.0]):
                content.planar_normals[joint.get("name")] = normal
    return content


def urdf_mimics(source: URDFSource) -> list[MimicJoint]:
    """The mimic relations of ``source`` (checked as in :func:`check_urdf`), without checking
    the rest of the document (a URDF that Pinocchio has already parsed)."""
    return read_mimics(_children(_parse(source), "joint"), source.error)


def _parse(source: URDFSource) -> etree._Element:
    """The root element of ``source``; no entities resolved, no network."""
    if not starts_xml(source.data):
        raise source.error(f"not XML text: it starts with {preview(source.data, 20)}, not '<'")
    parser = etree.XMLParser(resolve_entities=False, no_network=True,
                             encoding=None if source.path else "utf-8")
    try:
        return etree.fromstring(source.data, parser)
    except etree.XMLSyntaxError as exc:
        raise source.error(f"not well-formed XML: {exc.msg}") from None


def _tag(element: etree._Element) -> str:
    """The element's name as URDF parsers read it (a prefix is part of the name)."""
    local = etree.QName(element).localname
    return f"{element.prefix}:{local}" if element.prefix else local


def _children(element: etree._Element, tag: str) -> list[etree._Element]:
    return [e for e in element if isinstance(e.tag, str) and _tag(e) == tag]


def _names(elements: list[etree._Element], kind: str, source: URDFSource) -> list[str]:
    """The ``name`` of each element; :class:`URDFError` if one is missing or repeated."""
    names: list[str] = []
    seen: set[str] = set()
    for element in elements:
        name = element.get("name")
        if not name:
            raise source.error(f"a <{kind}> without a name (line {element.sourceline})")
        if name in seen:
            raise source.error(f"two {kind}s named {name!r} (line {element.sourceline})")
        seen.add(name)
        names.append(name)
    return names


def _link_of(joint: etree._Element, end: str) -> str | None:
    """The link named by the joint's ``<parent link=..>`` or ``<child link=..>``."""
    found = _children(joint, end)
    return found[0].get("link") if found else None


def _check_joint(joint: etree._Element, links: set[str], source: URDFSource) -> None:
    """Type, parent and child links, origin, axis and limits of one joint."""
    name = joint.get("name")
    kind = joint.get("type")
    if kind not in JOINT_TYPES:
        raise source.error(f"joint {name!r} has type {kind!r}; URDF joint types are "
                           f"{list(JOINT_TYPES)}")
    for end in ("parent", "child"):
        link = _link_of(joint, end)
        if not link:
            raise source.error(f"joint {name!r} has no <{end} link=\"...\"/>")
        if link not in links:
            close = difflib.get_close_matches(link, links, n=3)
            hint = f"; close names: {close}" if close else ""
            raise source.error(f"joint {name!r} names {end} link {link!r}, which is not "
                               f"defined{hint}")
    what = f"joint {name!r}"
    for origin in _children(joint, "origin"):
        _check_origin(origin, f"{what}: <origin>", source)
    if kind in _AXIS_TYPES:
        _check_axis(joint, what, source)
    for limit in _children(joint, "limit"):
        _check_limit(limit, kind, what, source)


def _check_link(link: etree._Element, source: URDFSource) -> None:
    """The ``<origin>`` of each ``<visual>``, ``<collision>`` and ``<inertial>`` of a link."""
    for part in link:
        if isinstance(part.tag, str):
            for origin in _children(part, "origin"):
                _check_origin(origin, f"link {link.get('name')!r}: <{_tag(part)}><origin>",
                              source)


def _check_origin(origin: etree._Element, what: str, source: URDFSource) -> None:
    """``xyz`` and ``rpy`` (each defaulting to 0 0 0) are three finite numbers."""
    for attribute in ("xyz", "rpy"):
        _vector(origin, attribute, what, source)


def _check_axis(joint: etree._Element, what: str, source: URDFSource) -> None:
    """A moving joint's ``<axis xyz>`` (default 1 0 0) is finite and of norm at least
    :data:`AXIS_EPSILON` (it can be normalised)."""
    for axis in _children(joint, "axis"):
        xyz = _vector(axis, "xyz", f"{what}: <axis>", source)
        if xyz is None:
            continue
        norm = math.hypot(*xyz)
        if norm == 0.0:
            raise source.error(f"{what}: <axis xyz={axis.get('xyz')!r}> is zero-length; a "
                               f"{joint.get('type')} joint needs a direction")
        if norm < AXIS_EPSILON:
            raise source.error(f"{what}: <axis xyz={axis.get('xyz')!r}> has norm {norm:.3g}, "
                               f"below {AXIS_EPSILON:g}: too short to be normalised into a "
                               "direction")


def _check_limit(limit: etree._Element, kind: str, what: str, source: URDFSource) -> None:
    """The ``<limit>`` values are finite numbers, effort and velocity are >= 0, and
    ``lower <= upper`` on revolute and prismatic joints (``lower > upper`` would leave the joint
    unlimited)."""
    values = {key: _number(limit, key, f"{what}: <limit>", source)
              for key in ("lower", "upper", "effort", "velocity") if limit.get(key) is not None}
    for key in ("effort", "velocity"):
        if values.get(key, 0.0) < 0.0:
            raise source.error(f"{what}: <limit {key}={limit.get(key)!r}> is negative")
    lower, upper = values.get("lower", 0.0), values.get("upper", 0.0)
    if kind in _LIMITED_TYPES and lower > upper:
        raise source.error(f"{what}: <limit lower={limit.get('lower')!r} "
                           f"upper={limit.get('upper')!r}> has lower > upper")


def _vector(element: etree._Element, attribute: str, what: str,
            source: URDFSource) -> tuple[float, float, float] | None:
    """The attribute as three finite numbers (None if absent)."""
    text = element.get(attribute)
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise source.error(f"{what} {attribute}={text!r} is not three finite numbers")
    return values


def _number(element: etree._Element, attribute: str, what: str, source: URDFSource) -> float:
    """The attribute as one finite number."""
    text = element.get(attribute)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise source.error(f"{what} {attribute}={text!r} is not a finite number")
    return value


def _check_tree(links: list[str], parents: dict[str, etree._Element],
                source: URDFSource) -> None:
    """The links joined by ``parents`` (child link -> its joint) form one tree: no cycle,
    exactly one root."""
    done: set[str] = set()
    for start in links:
        path: list[str] = []
        on_path: set[str] = set()  # path as a set: the walk stays linear in the chain's length
        link: str | None = start
        while link in parents and link not in done and link not in on_path:
            path.append(link)
            on_path.add(link)
            link = _link_of(parents[link], "parent")
        if link in path:
            cycle = (path[path.index(link):] + [link])[::-1]  # parent -> child order
            joints = [parents[child].get("name") for child in cycle[1:]]
            raise source.error(f"the links {' -> '.join(map(repr, cycle))} form a cycle "
                               f"(joints {joints})")
        done.update(path)
    roots = [link for link in links if link not in parents]
    if len(roots) > 1:
        raise source.error(f"several root links {name_list(roots)} (links that are no joint's "
                           "child); a URDF robot is one tree")


def _check_depth(links: list[str], parents: dict[str, etree._Element],
                 source: URDFSource) -> None:
    """The tree is at most :data:`MAX_DEPTH` links deep (linear in its size: each link's depth
    is computed once)."""
    depth: dict[str, int] = {}
    for start in links:
        path: list[str] = []
        link: str | None = start
        while link is not None and link not in depth:
            path.append(link)
            joint = parents.get(link)
            link = None if joint is None else _link_of(joint, "parent")
        base = -1 if link is None else depth[link]
        for k, name in enumerate(reversed(path)):
            depth[name] = base + 1 + k
            if depth[name] > MAX_DEPTH:
                raise source.error(
                    f"link {name!r} is {depth[name]} links below the root: deeper than "
                    f"{MAX_DEPTH}, beyond which Pinocchio's recursive parser may overflow the "
                    "stack and kill the interpreter")
