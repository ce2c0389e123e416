"""Comparing a run's results on the cluster with `carlos run` of the same manifest."""

from __future__ import annotations

import hashlib
import json
import re
from typing import Any

#: fields of a per-index summary that measure the machine, not the simulation
MACHINE_FIELDS = frozenset({"wallSeconds", "attempts", "outputUrl", "startedAt", "finishedAt", "host"})


def verdict(summary: dict[str, Any]) -> dict[str, Any]:
    """A per-index summary without what differs between machines (wall time, attempts)."""
    return {k: v for k, v in summary.items() if k not in MACHINE_FIELDS}


def junit(text: str) -> str:
    """junit.xml without its wall times."""
    return re.sub(r' time="[0-9.]+"', "", text)


def index_files(store: Any, run: str) -> dict[int, dict[str, bytes]]:
    """Every index folder of a run: {index: {file name: bytes}} for summary.json and recording.mcap."""
    found: dict[int, dict[str, bytes]] = {}
    for key in store.list(f"{run}/"):
        parts = key.split("/")
        if len(parts) == 3 and parts[1].isdigit() and parts[2] in ("summary.json", "recording.mcap"):
            found.setdefault(int(parts[1]), {})[parts[2]] = store.get_bytes(key)
    return found


def digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def summaries(files: dict[int, dict[str, bytes]]) -> dict[int, dict[str, Any]]:
    return {i: verdict(json.loads(f["summary.json"])) for i, f in files.items() if "summary.json" in f}
