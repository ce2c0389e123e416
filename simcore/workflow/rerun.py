"""`carlos rerun RESULTS --failed`: a new run, `<run>-rerun`, of the same spec over the failed and errored
indexes only (same permutations and seeds: index i of the new run is index i of the old one), written
beside the old run. Scenario paths relative to the original manifest are resolved through the absolute
path each recording names, or against `--base-dir`."""

from __future__ import annotations

import io
from pathlib import Path

from simcore.errors import BadInput
from simcore.results import RunResults
from simcore.spec import SimulationRun


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


def rerun_spec(results: RunResults, base_dir: Path | None) -> tuple[SimulationRun, list[int], Path]:
    """(the new run, the indexes to run, the base directory for its relative paths)."""
    if results.spec is None:
        raise BadInput(f"{results.url}/run.yaml is not a spec this version reads", field="RESULTS_URL")
    failed = [int(s["index"]) for s in results.indexes if s["status"] != "passed"]
    if not failed:
        raise BadInput(f"no failed or errored index in {results.url}: nothing to rerun", field="--failed")
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
