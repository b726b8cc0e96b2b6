"""How the viewer draws runs: each method's colour and name, the desired path's colour, colours."""

from __future__ import annotations

import numpy as np

#: Colours of the methods (as in the figures), as 0xRRGGBB.
METHOD_COLORS = {"sjt": 0x1F77B4, "jt": 0xD62728, "jp": 0x2CA02C, "dls": 0x9467BD}
#: What the method names stand for, for the page's legend.
METHOD_NAMES = {"sjt": "scaled Jacobian transpose", "jt": "Jacobian transpose",
                "jp": "Jacobian pseudoinverse", "dls": "damped least squares"}
#: Colour of the paper's exact SJT (eq. 21) where it is drawn beside the package's SJT.
PAPER_SJT_COLOR = 0x8C564B
#: Colour of a run whose method has none above.
OTHER_COLOR = 0xFF7F0E
#: Colours for further runs of a robot whose method's colour is taken (several SJT variants).
EXTRA_COLORS = (0xFF7F0E, 0x17BECF, 0x8C564B, 0xE377C2, 0xBCBD22, 0x7F7F7F)
#: Colour of the desired path and of the target marker.
DESIRED_COLOR = 0x222222
#: Colour of the support polygon and of the centre of mass's ground projection.
SUPPORT_COLOR = 0x2E8B57

_NAMED = {"blue": 0x1F77B4, "red": 0xD62728, "green": 0x2CA02C, "purple": 0x9467BD,
          "orange": 0xFF7F0E, "black": 0x000000, "gray": 0x7F7F7F, "white": 0xFFFFFF}


def to_int(color) -> int:
    """``0xRRGGBB``, a name in ``_NAMED``, or an (r, g, b) triple in [0, 1], as an int."""
    if isinstance(color, str):
        if color not in _NAMED:
            raise ValueError(f"color must be one of {sorted(_NAMED)}, an int or an RGB triple")
        return _NAMED[color]
    if isinstance(color, (int, np.integer)):
        return int(color)
    rgb = np.clip(np.asarray(color, dtype=float)[:3], 0.0, 1.0)
    return int(rgb[0] * 255) << 16 | int(rgb[1] * 255) << 8 | int(rgb[2] * 255)


def css(color: int) -> str:
    """``0xRRGGBB`` as a CSS colour, ``#rrggbb``."""
    return f"#{color:06x}"


def method_color(method: str) -> str:
    """The CSS colour (``#rrggbb``, what matplotlib takes) of ``method`` ("sjt", "jt", "jp",
    "dls", or "sjt-paper" for eq. 21), as the viewer's pages draw it: one palette for the pages
    and the notebooks' plots."""
    if method == "sjt-paper":
        return css(PAPER_SJT_COLOR)
    return css(METHOD_COLORS.get(method, OTHER_COLOR))
