"""The state of a meshcat scene, kept in this process so that a page can be written from it.

:class:`SceneRecord` is what ``meshcat.Visualizer(window=...)`` sends its commands to. Like
meshcat's server, it keeps for each node the last object, the properties set since then, the
last transform, and the last animation, and replays them in that order. It also passes every
command on to a live meshcat server when it has one. So a static page needs no server, and the
page is built from the scene itself rather than from the server's own HTML.

Commands are kept lowered (as the dicts meshcat packs), and packed only when the page is made:
an animation sent again as runs are added is packed once. They are packed with msgpack, as
meshcat packs them, but with single-precision floats: that is 1e-7 relative, well below a
pixel, and nearly halves an animation's size.
"""

from __future__ import annotations

import umsgpack


class _Node(dict):
    """A scene node: its children by name, and the lowered commands that set it up."""

    def __init__(self) -> None:
        super().__init__()
        self.object: dict | None = None
        self.properties: list[dict] = []
        self.transform: dict | None = None
        self.animation: dict | None = None

    def find(self, path: str) -> _Node:
        node = self
        for name in filter(None, path.split("/")):
            node = node.setdefault(name, _Node())
        return node

    def walk(self):
        yield self
        for child in self.values():
            yield from child.walk()


class SceneRecord:
    """A meshcat window that records the scene and forwards each command to ``live``, if any."""

    def __init__(self, live=None):
        self.live = live
        self.root = _Node()

    @property
    def web_url(self) -> str | None:
        """The live server's page (what ``meshcat.Visualizer.url()`` reads), or None."""
        return None if self.live is None else self.live.web_url

    def send(self, command) -> None:
        """Record a meshcat command (``SetObject``, ``SetTransform``, ...) and forward it."""
        lowered = command.lower()
        kind, path = lowered["type"], lowered.get("path", "")
        if kind == "delete":
            self._delete(path)
        elif kind == "set_object":
            node = self.root.find(path)
            node.object, node.properties = lowered, []
        elif kind == "set_property":
            self.root.find(path).properties.append(lowered)
        elif kind == "set_transform":
            self.root.find(path).transform = lowered
        elif kind == "set_animation":
            self.root.find(path).animation = lowered
        else:
            raise ValueError(f"a scene record cannot replay {kind!r} commands")
        if self.live is not None:
            self.live.send(command)

    def _delete(self, path: str) -> None:
        names = [n for n in path.split("/") if n]
        if not names:
            self.root = _Node()
            return
        self.root.find("/".join(names[:-1])).pop(names[-1], None)

    def lowered(self) -> list[dict]:
        """The lowered commands that rebuild the scene: objects, properties and transforms node
        by node, then the animations, whose targets must exist by then."""
        lowered: list[dict] = []
        for node in self.root.walk():
            lowered.extend(c for c in (node.object, *node.properties, node.transform) if c)
        lowered.extend(node.animation for node in self.root.walk() if node.animation)
        return lowered

    def commands(self) -> list[bytes]:
        """:meth:`lowered`, packed (single-precision floats)."""
        return [umsgpack.packb(c, force_float_precision="single") for c in self.lowered()]
