"""The meshcat viewer: robots, animated tracking runs, the demo page (needs the viewer extra)."""

from ..extras import require

require("meshcat", "trimesh", "fast_simplification")

from .server import ServerTimeout  # noqa: E402
from .style import METHOD_COLORS  # noqa: E402
from .viewer import Viewer  # noqa: E402

__all__ = ["METHOD_COLORS", "ServerTimeout", "Viewer"]
