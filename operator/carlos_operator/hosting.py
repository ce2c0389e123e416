"""What the search rounds (searching.py), input reading (inputs.py, reading.py) and the writes (apply.py) use
of the controller: a Protocol, so none of them imports controller.py (which imports them) — no import
circle."""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Protocol

from carlos_operator.builders import OperatorSettings, Output
from carlos_operator.kube import Kube
from carlos_operator.runstate import RunState
from carlos_operator.scratch import ScratchFolders

Key = tuple[str, str]


class Host(Protocol):
    """The controller as its helpers see it (carlos_operator.controller.Controller implements it)."""

    kube: Kube
    settings: OperatorSettings
    batch: int
    backoff: float
    scratch: ScratchFolders
    store_factory: Callable[[Kube, str, Output], Any]
    jobs: dict[Key, dict[str, Any]]
    _lock: threading.Lock
    _fetch: ThreadPoolExecutor

    def _publish(self, state: RunState, status: dict[str, Any]) -> None: ...

    def enqueue(self, key: Key) -> None: ...

    def _job_gone(self, state: RunState, name: str | None = None) -> None: ...

    def _check_pods(self, state: RunState, job: dict[str, Any], status: dict[str, Any]) -> None: ...

    def _transition(self, state: RunState, before: str | None, status: dict[str, Any]) -> None: ...

    def _finalize(self, state: RunState, job: dict[str, Any] | None) -> None: ...

    def _maybe(self, state: RunState, index: int) -> dict[str, Any] | None: ...
