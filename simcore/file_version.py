"""Keys for per-process caches of what is derived from a file (a parsed scenario or catalog, a converted
road network): a warm sweep worker reads the same files run after run.

A cache is keyed by the file's bytes (`content_key`: the path and the SHA-256 of the bytes the derived value
was made from), never by its modification time or size: an edit within the file system's timestamp
granularity, keeping the size, is read all the same. Hashing a scenario or road file of a few dozen kB costs
microseconds; parsing it costs milliseconds. Every cache is bounded (`BoundedCache`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Generic, TypeVar

#: a file's absolute path and the SHA-256 digest of its bytes
ContentKey = tuple[str, bytes]

K = TypeVar("K")
V = TypeVar("V")


def content_key(path: Path, data: bytes) -> ContentKey:
    """The cache key of `data`, the bytes read from `path`."""
    return (str(path.absolute()), hashlib.sha256(data).digest())


class BoundedCache(Generic[K, V]):
    """A dict of at most `size` entries; the least recently used goes first (a worker over a long sweep of
    many scenarios never grows without bound)."""

    __slots__ = ("_entries", "size")

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"size must be at least 1, not {size}")
        self.size = size
        self._entries: dict[K, V] = {}

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, key: object) -> bool:
        return key in self._entries

    def __iter__(self) -> Iterator[K]:
        return iter(list(self._entries))

    def get(self, key: K) -> V | None:
        value = self._entries.pop(key, None)
        if value is not None:
            self._entries[key] = value  # most recently used last
        return value

    def put(self, key: K, value: V) -> V:
        entries = self._entries
        entries.pop(key, None)
        entries[key] = value
        while len(entries) > self.size:
            del entries[next(iter(entries))]
        return value

    def get_or_make(self, key: K, make: Callable[[], V]) -> V:
        """The entry of `key`, made (and kept) when there is none."""
        value = self.get(key)
        return self.put(key, make()) if value is None else value

    def clear(self) -> None:
        self._entries.clear()
