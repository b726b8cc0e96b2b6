"""The decorator of every compiled kernel, and where their machine code is cached."""

from __future__ import annotations

import os

import numba
from numba.core import config as _numba_config

#: Where the compiled kernels are cached (unless ``NUMBA_CACHE_DIR`` says otherwise): a
#: per-user folder, so that nothing is ever written into the installed package.
CACHE_DIR = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"),
                         "sjt-pin", "numba")


def compiled(function=None, *, inline: bool = False):
    """``numba.njit(cache=True, nogil=True)``, caching under :data:`CACHE_DIR`.

    ``inline=True`` (``@compiled(inline=True)``) inlines a small helper into its callers at
    numba's IR level, which saves the cost of a call that passes arrays. numba reads its cache
    folder when a function is decorated; it is set only for the duration of the decoration, so
    other packages in the same process keep their own setting.
    """
    if function is None:
        return lambda f: compiled(f, inline=inline)
    saved = _numba_config.CACHE_DIR
    if not saved:
        _numba_config.CACHE_DIR = CACHE_DIR
    try:
        return numba.njit(cache=True, nogil=True, inline="always" if inline else "never")(
            function)
    finally:
        _numba_config.CACHE_DIR = saved
