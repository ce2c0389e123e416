"""What the controller keeps of a run and of a Job between events (shared by the controller and the search
rounds, so neither imports the other)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from carlos_operator.builders import Output
from carlos_operator.status import RUNS_ANNOTATION, RUNS_PER_POD_ANNOTATION, Tally
from simcore.search import driver
from simcore.search.space import Dimension
from simcore.spec import SimulationRun


@dataclass
class SearchProgress:
    """What the operator keeps of one search between passes (rebuilt from the store after a restart)."""

    scenario_name: str  # the scenario as failing.xosc names it
    space: list[Dimension]
    log: list[dict[str, Any]] = field(default_factory=list)
    points: list[dict[str, Any]] = field(default_factory=list)
    loaded: bool = False  # the stored state was read
    round: driver.Round | None = None  # the round asked (its study tells the results)
    created: set[int] = field(default_factory=set)  # rounds whose Job this process created or adopted
    stopped: bool = False
    #: wall seconds of the runs told so far (their mean sizes the next round's slices)
    wall_seconds: list[float] = field(default_factory=list)


@dataclass
class RunState:
    """What the controller remembers of one run (rebuilt from the cluster and the store after a restart)."""

    body: dict[str, Any]
    uid: str
    run: SimulationRun | None = None
    output: Output | None = None
    tally: Tally | None = None
    store: Any = None
    ensured: bool = False
    last_status: dict[str, Any] = field(default_factory=dict)
    generation: int | None = None
    job_seen: bool = False  # its Job existed (created, adopted, or the status shows it started)
    held: bool = False  # suspended with a queueName: the Job is not created yet
    waits: int = 0  # consecutive waits for a prerequisite (the backoff exponent)
    pods_checked: float = 0.0  # monotonic time of the last pod check
    stuck: tuple[str, str] | None = None  # (reason, message) of a pod that cannot start
    search: SearchProgress | None = None  # a search's rounds (searching.py)


def slim_job(job: dict[str, Any]) -> dict[str, Any]:
    """What the controller needs of a Job (its pod template is most of its size: kept out of memory)."""
    meta = job.get("metadata") or {}
    spec = job.get("spec") or {}
    return {
        "metadata": {
            "name": meta.get("name"),
            "namespace": meta.get("namespace"),
            "uid": meta.get("uid"),
            "annotations": {
                k: v
                for k, v in (meta.get("annotations") or {}).items()
                if k in (RUNS_PER_POD_ANNOTATION, RUNS_ANNOTATION)
            },
            "ownerReferences": [
                {"kind": o.get("kind"), "name": o.get("name"), "uid": o.get("uid")}
                for o in meta.get("ownerReferences") or []
            ],
        },
        "spec": {"suspend": spec.get("suspend"), "parallelism": spec.get("parallelism")},
        "status": job.get("status") or {},
    }
