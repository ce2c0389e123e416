"""Read a run's results back from its object store (DESIGN.md, "Object store layout").

`open_results(url)` takes the run's own URL (`file://…/results/<run>`, `s3://bucket/prefix/<run>`, as
`carlos run` prints it) or the output URL holding exactly one run. Everything here only reads.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from simcore.errors import BadInput, CarlosError
from simcore.spec import SimulationRun
from simcore.store import Store, StoreError, open_store

_INDEX_SUMMARY = re.compile(r"^(\d+)/summary\.json$")


@dataclass
class RunResults:
    """What a finished (or running) run left in the store; `store` is rooted at the run's prefix."""

    url: str
    store: Store
    name: str
    spec: SimulationRun | None
    summary: dict[str, Any] | None
    indexes: list[dict[str, Any]] = field(default_factory=list)

    def failed(self) -> list[dict[str, Any]]:
        """Index summaries of required runs that failed or errored, by index."""
        return [s for s in self.indexes if s["status"] != "passed" and not s.get("optional", False)]

    def mcap_url(self, index: int) -> str | None:
        key = f"{index}/recording.mcap"
        return self.store.url_for(key) if self.store.exists(key) else None


def _open(url: str, field_name: str) -> Store:
    try:
        return open_store(url)
    except ValueError as exc:
        raise BadInput(str(exc), field=field_name) from None


def _child_runs(store: Store) -> list[str]:
    return sorted(
        {key.split("/")[0] for key in store.list() if key.count("/") == 1 and key.endswith("/run.yaml")}
    )


def open_results(url: str, *, field_name: str = "RESULTS_URL") -> RunResults:
    """The run at `url` (or the only run below it), with its spec, run-level summary and index summaries.

    Bad input (exit 2) when nothing of a run is there or the output holds several runs."""
    url = url.rstrip("/")
    store = _open(url, field_name)
    if not store.exists("run.yaml"):
        runs = _child_runs(store)
        if len(runs) != 1:
            found = (
                f"it holds the runs {', '.join(runs)}: add one to the URL" if runs else "no run.yaml there"
            )
            raise BadInput(f"{url} is not the results of one run ({found})", field=field_name)
        url = f"{url}/{runs[0]}"
        store = _open(url, field_name)
    try:
        raw_spec = yaml.safe_load(store.get_bytes("run.yaml"))
        summary = json.loads(store.get_bytes("summary.json")) if store.exists("summary.json") else None
        summaries = []
        for key in store.list():
            if _INDEX_SUMMARY.match(key):
                summaries.append(json.loads(store.get_bytes(key)))
    except StoreError as exc:
        raise BadInput(str(exc), field=field_name) from None
    try:
        spec: SimulationRun | None = SimulationRun.model_validate(raw_spec)
    except ValueError:
        spec = None  # written by another version: the report works from the summaries alone
    name = spec.name if spec is not None else url.rsplit("/", 1)[-1]
    summaries.sort(key=lambda s: int(s["index"]))
    if (
        spec is not None and spec.spec.search is None
    ):  # parameters in the manifest's order (summaries written before kept them sorted)
        summaries = _in_manifest_order(spec, summaries)
    return RunResults(url=url, store=store, name=name, spec=spec, summary=summary, indexes=summaries)


def _in_manifest_order(spec: SimulationRun, summaries: list[dict[str, Any]]) -> list[dict[str, Any]]:
    from simcore.evaluation.report import in_manifest_order
    from simcore.plan import Plan

    try:
        plan = Plan(spec.spec)
    except CarlosError:  # a plan this machine cannot build (a ConfigMap's distribution): order as stored
        return summaries
    ordered = []
    for summary in summaries:
        index = summary.get("index")
        if isinstance(index, int) and 0 <= index < len(plan):
            summary = in_manifest_order(summary, list(plan[index].parameters))
        ordered.append(summary)
    return ordered


class PrefixedStore:
    """The part of a store under `prefix/` as a store of its own (keys relative to the prefix)."""

    def __init__(self, store: Store, prefix: str) -> None:
        self.store = store
        self.prefix = prefix.strip("/") + "/"

    def put_file(self, key: str, local_path: str | os.PathLike[str]) -> None:
        self.store.put_file(self.prefix + key, local_path)

    def put_bytes(self, key: str, data: bytes) -> None:
        self.store.put_bytes(self.prefix + key, data)

    def get_bytes(self, key: str) -> bytes:
        return self.store.get_bytes(self.prefix + key)

    def exists(self, key: str) -> bool:
        return self.store.exists(self.prefix + key)

    def list(self, prefix: str = "") -> list[str]:
        return [key[len(self.prefix) :] for key in self.store.list(self.prefix + prefix)]

    def sync(self) -> None:
        self.store.sync()

    def url_for(self, key: str) -> str:
        return self.store.url_for(self.prefix + key)
