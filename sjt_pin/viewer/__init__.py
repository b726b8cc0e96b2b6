"""The meshcat viewer: robots, animated tracking runs, the demo page (imports meshcat)."""

from .server import ServerTimeout
from .style import METHOD_COLORS
from .viewer import Viewer

__all__ = ["METHOD_COLORS", "ServerTimeout", "Viewer"]
