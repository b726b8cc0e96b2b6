"""The state that the parts of :class:`sjt_pin.limits.collision.CollisionLimit` share: the
types of the attributes more than one of its parts (the mixins of ``collision_pairs``,
``collision_tables``, ``collision_broad_phase``, ``collision_moving`` and ``collision_rows``)
reads or writes, declared once for the type checker (no values: the parts set them)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..kernels import Skip


class CollisionState:
    """The declared state of a :class:`~sjt_pin.limits.collision.CollisionLimit`."""

    #: the pairs of the rows and within influence at the last rows() (collision.py)
    active: list[int]
    within: list[int]
    _witness_count: int
    _tick: float
    _version: int  # the obstacles' poses' version, raised by each move()
    #: the last broad phase: (obstacles' version, q, its pairs, each pair's gap, its pairs)
    _reference: tuple[int, np.ndarray, np.ndarray, np.ndarray, list] | None
    _floor_q: np.ndarray | None
    _skip: Skip | None
    _views: tuple
    _reaches: tuple[object, np.ndarray | None]
    _cache: tuple | None
    _bounds: tuple[float, np.ndarray | None, bool, tuple] | None
    _args: dict  # what a copy is made anew from (collision.py)
    _stamps: list  # each obstacle's last time-stamped pose, (time, pose) or None (move())
    _checked: bool  # whether the start's check ran (collision_pairs.py)

    if TYPE_CHECKING:  # the rest of the state: arrays and coal's objects the parts set
        def __getattr__(self, name: str) -> Any: ...
