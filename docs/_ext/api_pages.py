"""One API page per public name: ``sjt_pin.__all__`` and the public names of the packages a user
extends or draws with (``sjt_pin.limits``, ``sjt_pin.limits.collision``, ``sjt_pin.methods``,
``sjt_pin.viewer``), and the classes a public method or attribute returns without their module
exporting them (``RETURNED``).

The pages are written into ``docs/api/generated/`` when the build starts (not committed); the
hand-grouped index ``docs/api/index.md`` links them, and ``tests/test_docs.py`` checks that it
links every one. A reference a docstring makes by a short name (``:class:`Limit```, from a
module where ``Limit`` is not imported) is resolved to the one documented object of that name.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

from sphinx.util.nodes import make_refnode

#: the packages whose ``__all__`` gets pages, in the order of the index
PACKAGES = ("sjt_pin", "sjt_pin.limits", "sjt_pin.limits.collision", "sjt_pin.methods",
            "sjt_pin.viewer")
#: ``(module, name)`` of the classes a public API returns without exporting them
RETURNED = (
    ("sjt_pin.joint_move", "JointMove"),  # Solver.move_to's
    ("sjt_pin.robot_frames", "FrameInfo"),  # Robot.frames'
    ("sjt_pin.mimic", "MimicJoint"),  # Robot.mimic_joints'
    ("sjt_pin.step_info", "LevelInfo"),  # StepInfo.levels'
)


def public_names() -> list[tuple[str, str]]:
    """``(package, name)`` for every public name, each object once (a name a sub-package
    shares with ``sjt_pin`` is documented as ``sjt_pin``'s)."""
    seen: set[int] = set()
    names = []
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            obj = getattr(module, name)
            if package != "sjt_pin" and id(obj) in seen:
                continue
            if name != "DifferentialIKSolver":  # an alias: its page says of what
                seen.add(id(obj))
            names.append((package, name))
    names.extend(RETURNED)
    return names


def page(package: str, name: str) -> str:
    """The reStructuredText of one name's page."""
    obj = getattr(importlib.import_module(package), name)
    title = f"{package}.{name}"
    if inspect.isclass(obj) and issubclass(obj, BaseException):
        body = f".. autoexception:: {title}\n   :members:\n   :show-inheritance:\n"
    elif inspect.isclass(obj) and obj.__name__ != name:  # an alias
        body = (f".. autoclass:: {title}\n   :no-members:\n\n"
                f"   An alias of :class:`{package}.{obj.__name__}`.\n")
    elif inspect.isclass(obj):
        body = (f".. autoclass:: {title}\n   :members:\n   :show-inheritance:\n"
                "   :special-members: __call__\n")
        # a class built from mixins (CollisionLimit's parts) documents their public members
        # as its own: those of its first public base (and object) stay on that base's page
        public = [b for b in obj.__bases__ if not b.__name__.endswith("Mixin")]
        if len(public) < len(obj.__bases__):
            body += f"   :inherited-members: {public[0].__name__ if public else 'object'}\n"
    elif callable(obj):
        body = f".. autofunction:: {title}\n"
    else:  # data: documented where its ``#:`` comment is, in the module that defines it
        body = f".. autodata:: {_home(package, name, obj)}\n"
    return f"{title}\n{'=' * len(title)}\n\n.. currentmodule:: {package}\n\n{body}"


def _home(package: str, name: str, obj) -> str:
    """The module of ``package`` where the data ``obj`` is assigned (its comment is there)."""
    import pkgutil

    root = importlib.import_module(package)
    for info in pkgutil.iter_modules(root.__path__):
        module = importlib.import_module(f"{package}.{info.name}")
        if getattr(module, name, None) is obj:
            return f"{package}.{info.name}.{name}"
    return f"{package}.{name}"


def write_pages(app) -> None:
    folder = Path(app.srcdir) / "api" / "generated"
    folder.mkdir(parents=True, exist_ok=True)
    wanted = {}
    for package, name in public_names():
        wanted[f"{package}.{name}.rst"] = page(package, name)
    for stale in folder.glob("*.rst"):
        if stale.name not in wanted:
            stale.unlink()
    for filename, text in wanted.items():
        path = folder / filename
        if not path.exists() or path.read_text() != text:  # unchanged pages are not rebuilt
            path.write_text(text)


def resolve_short_names(app, env, node, contnode):
    """A Python reference by a short name that nothing else resolved: the documented object
    whose full name ends with it, when exactly one does (after preferring the objects of the
    referring module's package)."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    if not target:
        return None
    domain = env.get_domain("py")
    matches = [(full, obj) for full, obj in domain.objects.items()
               if full == target or full.endswith("." + target)]
    if len(matches) > 1:  # a public name beside the same name deeper down: the public one
        matches = [m for m in matches if m[0] == "sjt_pin." + target]
    if len(matches) != 1:
        return None
    full, obj = matches[0]
    return make_refnode(app.builder, node["refdoc"], obj.docname, obj.node_id, contnode, full)


def setup(app):
    app.connect("builder-inited", write_pages)
    app.connect("missing-reference", resolve_short_names)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

