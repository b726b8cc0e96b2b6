"""The optional parts of the package and the extras that install them.

The core (robots, tasks, methods, limits, solvers, ``solve``) needs Pinocchio, NumPy and lxml.
The viewer needs ``sjt-pin[viewer]`` (meshcat, trimesh and the mesh readers); the paper's
figures and its URDF generator need ``sjt-pin[paper]`` (matplotlib, yourdfpy).
"""

from __future__ import annotations

import importlib

#: the extra that installs each optional module
EXTRAS = {
    "meshcat": "viewer", "trimesh": "viewer", "fast_simplification": "viewer",
    "collada": "viewer", "matplotlib": "paper", "yourdfpy": "paper",
}


def require(*modules: str) -> None:
    """Import ``modules``, or raise ``ImportError`` naming the extra that installs them."""
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            extra = EXTRAS.get(name, "dev")
            raise ImportError(f"{name} is not installed: this part of sjt-pin needs its "
                              f"'{extra}' extra: python -m pip install 'sjt-pin[{extra}]'"
                              ) from exc
