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


def messages(recording: bytes) -> list[tuple[str, int, str]]:
    """Every message of a recording as (topic, log time, digest of its bytes), in a canonical order: the pod
    path carries topics over DDS, which delivers messages of the same instant on different topics in no
    fixed order, so the file's bytes differ where the messages do not."""
    import io

    from mcap.reader import make_reader

    reader = make_reader(io.BytesIO(recording))
    return sorted(
        (channel.topic, message.log_time, digest(message.data))
        for _, channel, message in reader.iter_messages(log_time_order=False)
    )


def by_point(files: dict[int, dict[str, bytes]]) -> dict[str, dict[str, Any]]:
    """Per-index files keyed by what the index ran (scenario and parameter values), not by its number: the
    API server stores `spec.sweep.matrix` with its keys sorted, so on a cluster the permutations are numbered
    in that order, while `carlos run` numbers them in the manifest's order."""
    found = {}
    for data in files.values():
        summary = json.loads(data["summary.json"])
        # numbers as floats: the API server writes a YAML `15.0` back as JSON `15`
        values = sorted(
            (k, float(v) if isinstance(v, int | float) and not isinstance(v, bool) else v)
            for k, v in summary["parameters"].items()
        )
        key = json.dumps([summary["scenario"], values, summary["seed"]])
        found[key] = {"summary": verdict(summary), "recording": data.get("recording.mcap")}
    return found


def junit_cases(text: str) -> list[str]:
    """junit.xml's test cases, each with its parameters in a canonical order, without wall times and index
    numbers (see `by_point`)."""

    def canonical(match: re.Match[str]) -> str:
        return match.group(1) + ",".join(sorted(match.group(2).split(","))) + '"'

    cases = re.findall(r"<testcase name=\"[^\"]*\"[^>]*>", junit(text))
    return sorted(re.sub(r'^(<testcase name="[^\[]*)\[\d+\] ?([^"]*)"', canonical, case) for case in cases)
