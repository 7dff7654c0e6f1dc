"""Values worked out from immutable objects (schedules, paths), kept by those objects'
identities: the same object is asked about over and over while a team's timings are
compared, and hashing its content would cost more than the work kept.

Each entry holds the objects it was worked out from, so that no identity is reused while the
entry stands; the memo is emptied whole when it is full (the objects asked about come in
waves, one planning run after another)."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

V = TypeVar("V")

__all__ = ["IdentityMemo"]


class IdentityMemo(Generic[V]):
    """At most ``size`` values, each keyed by the identities of the objects it was worked out
    from and by a hashable ``extra`` (the other arguments, exactly)."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._entries: dict[Hashable, tuple[tuple[object, ...], V]] = {}

    def get(self, objects: tuple[object, ...], extra: Hashable, make: Callable[[], V]) -> V:
        """The value kept for ``objects`` and ``extra``, else ``make()``, kept."""
        key = (*map(id, objects), extra)
        hit = self._entries.get(key)
        if hit is not None and all(k is o for k, o in zip(hit[0], objects, strict=True)):
            return hit[1]
        value = make()
        if len(self._entries) >= self._size:
            self._entries.clear()
        self._entries[key] = (objects, value)
        return value
