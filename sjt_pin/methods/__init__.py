"""The CLIK mappings M(J), one class per file (see :mod:`.base`)."""

from .base import Method
from .dls import DLS
from .jp import JP
from .jt import JT
from .sjt import SJT

METHODS: dict[str, type[Method]] = {cls.name: cls for cls in (SJT, JT, JP, DLS)}

__all__ = ["DLS", "JP", "JT", "METHODS", "Method", "SJT"]
