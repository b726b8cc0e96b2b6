"""The CLIK mappings M(J), one class per file (see :mod:`.base`)."""

from .base import Method
from .dls import DLS
from .jp import JP
from .jt import JT
from .sjt import SJT

__all__ = ["DLS", "JP", "JT", "Method", "SJT"]
