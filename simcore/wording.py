"""Words for counts in messages people read (terminal, report, Kubernetes conditions and events)."""

from __future__ import annotations

__all__ = ["plural"]


def plural(count: int, word: str, words: str | None = None) -> str:
    """`1 run`, `2 runs`, `0 runs`; `words` for an irregular plural (`1 index`, `2 indexes`) (pure)."""
    return f"{count} {word}" if count == 1 else f"{count} {words or word + 's'}"
