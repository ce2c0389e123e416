"""`carlos rerun RUN --failed`: a new run over the failed and errored indexes only, with the same
permutations and seeds.

- RUN a results URL (a local run): `<run>-rerun`, the same spec run over those indexes (index i of the new
  run is index i of the old one), written beside the old run. Scenario paths relative to the original
  manifest are resolved through the absolute path each recording names, or against `--base-dir`.
- RUN a SimulationRun's name on a cluster: a new SimulationRun `<run>-rerun` (or `-rerun-2`, … the first
  free name) with the old spec and `spec.sweep.indexes` set to the failed indexes (index k of the new run
  is index `indexes[k]` of the old sweep), created as `carlos submit` creates a run; the old run's inputs
  ConfigMap is copied into one owned by the new run."""

from __future__ import annotations

import copy
import io
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from simcore.errors import BadInput
from simcore.results import RunResults
from simcore.spec import SimulationRun
from simcore.workflow.submit import API_VERSION, Packed, inputs_name


def recorded_scenario_files(results: RunResults) -> dict[str, str]:
    """Scenario name → the scenario file its first recording names (`carlos.run` metadata)."""
    from mcap.reader import make_reader

    found: dict[str, str] = {}
    for summary in results.indexes:
        key = f"{summary['index']}/recording.mcap"
        if summary["scenario"] in found or not results.store.exists(key):
            continue
        for record in make_reader(io.BytesIO(results.store.get_bytes(key))).iter_metadata():
            if record.name == "carlos.run" and record.metadata.get("scenarioFile"):
                found[summary["scenario"]] = record.metadata["scenarioFile"]
    return found


def failed_indexes(results: RunResults) -> list[int]:
    """The failed and errored indexes of a run's results (BadInput when there is none)."""
    failed = [int(s["index"]) for s in results.indexes if s["status"] != "passed"]
    if not failed:
        raise BadInput(f"no failed or errored index in {results.url}: nothing to rerun", field="--failed")
    return failed


def rerun_name(name: str, taken: Callable[[str], bool]) -> str:
    """`<name>-rerun`, else `<name>-rerun-2`, `-3`, … the first name `taken` says is free (a DNS label)."""
    for n in range(1, 1000):
        suffix = "-rerun" if n == 1 else f"-rerun-{n}"
        candidate = f"{name[: 63 - len(suffix)].rstrip('-')}{suffix}"
        if not taken(candidate):
            return candidate
    raise BadInput(f"{name!r} has 999 reruns already: delete some", field="RUN")


def cluster_rerun(
    obj: Mapping[str, Any], failed: list[int], name: str, inputs: Mapping[str, str] | None
) -> Packed:
    """The rerun of the cluster run `obj` over its `failed` indexes as the objects `carlos submit` creates:
    the old spec with `spec.sweep.indexes` (composed with the old run's own selection), named `name`;
    `inputs`: the data of the old run's inputs ConfigMap, copied into the new run's (pure)."""
    spec = copy.deepcopy(dict(obj["spec"]))
    old = str(obj["metadata"]["name"])
    if spec.get("search") is not None:
        raise BadInput(
            f"{old!r} is a search: rerun its failing points as a sweep over its search/failing.xosc "
            "(spec.sweep.distribution)",
            field="RUN",
        )
    sweep = spec.setdefault("sweep", {})
    selected = sweep.get("indexes")
    sweep["indexes"] = [int(selected[i]) if selected else i for i in failed]
    spec.pop("suspend", None)
    body: dict[str, Any] = {
        "apiVersion": API_VERSION,
        "kind": "SimulationRun",
        "metadata": {"name": name, "namespace": obj["metadata"].get("namespace") or "default"},
        "spec": spec,
    }
    SimulationRun.model_validate(body)  # raises for a spec this version cannot run
    packed = Packed(run=body, configmap_name=inputs_name(name))
    old_inputs = inputs_name(old)
    refs = [s.get("configMapRef") for s in spec.get("scenarios", [])] + [
        sweep.get("distributionConfigMapRef")
    ]
    for ref in refs:
        if ref is not None and ref.get("name") == old_inputs and inputs is not None:
            ref["name"] = packed.configmap_name
            packed.files = dict(inputs)
    return packed


def rerun_spec(results: RunResults, base_dir: Path | None) -> tuple[SimulationRun, list[int], Path]:
    """(the new run, the indexes to run, the base directory for its relative paths)."""
    if results.spec is None:
        raise BadInput(f"{results.url}/run.yaml is not a spec this version reads", field="RESULTS_URL")
    failed = failed_indexes(results)
    body = results.spec.model_dump(mode="json", by_alias=True, exclude_none=True)
    if base_dir is None:
        recorded = recorded_scenario_files(results)
        for scenario in body["spec"]["scenarios"]:
            source = scenario.get("openscenario")
            if source is not None and "://" not in source:
                path = recorded.get(scenario["name"])
                if path is None or not Path(path).is_file():
                    raise BadInput(
                        f"scenario {scenario['name']!r} ({source}) is relative to the original manifest: give "
                        "its folder with --base-dir",
                        field="--base-dir",
                    )
                scenario["openscenario"] = Path(path).as_uri()
    body["metadata"]["name"] = f"{results.spec.name[:56]}-rerun"
    run = SimulationRun.model_validate(body)
    return run, failed, (base_dir or Path.cwd()).resolve()
