"""The meshcat viewer: robots, animated tracking runs, the demo page (imports meshcat)."""

from .viewer import METHOD_COLORS, Viewer

__all__ = ["METHOD_COLORS", "Viewer"]
