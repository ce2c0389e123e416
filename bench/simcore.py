"""Simulated seconds per wall second of the example scenarios.

For each example scenario (default parameters):
- warm: in this process, after one warm-up run, the median of REPEAT runs of the whole simulation
  (scenario engine + SUMO + metrics), with and without MCAP recording;
- process: a fresh Python process running the index through `carlos run` (imports, SUMO start, network from
  the cache, upload to a local folder), wall time of the whole command;
- baseline: libsumo alone stepping the same network with the same number of SUMO-driven vehicles for the same
  number of steps, measured in this run; `ratio` = warm time / baseline time (the cost of CARLOS on top of SUMO).

Prints a table and, as its last line, one JSON object with the figures. No assertions: machines are noisy.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore.evaluation.metrics import MetricsAccumulator  # noqa: E402
from simcore.manifest import parse_manifest  # noqa: E402
from simcore.pipeline import simulate  # noqa: E402
from simcore.plan import Plan  # noqa: E402
from simcore.scenario.xosc import load_scenario  # noqa: E402
from simcore.world.sumo import SumoWorld, prepare_network  # noqa: E402

SCENARIOS = ["cut-in", "braking", "curve-following", "obstacle"]
REPEAT = int(os.environ.get("BENCH_REPEAT", "3"))
STEP = 0.05


def manifest(name: str, recording: bool) -> dict[str, object]:
    return {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": f"bench-{name}"},
        "spec": {
            "scenarios": [
                {"name": name, "openscenario": str(ROOT / "examples" / "scenarios" / f"{name}.xosc")}
            ],
            "simulation": {"stepSeconds": STEP, "maxSeconds": 60},
            "recording": {"enabled": recording},
        },
    }


def warm(name: str, recording: bool) -> tuple[float, float]:
    """(median wall seconds, simulated seconds) of the simulation of one run in this process."""
    run = parse_manifest(manifest(name, recording), source="bench")
    point = Plan(run.spec)[0]
    scenario_file = ROOT / "examples" / "scenarios" / f"{name}.xosc"
    times = []
    sim = 0.0
    for attempt in range(REPEAT + 1):
        with tempfile.TemporaryDirectory() as out:
            started = time.perf_counter()
            sim = simulate(run, point, scenario_file, Path(out)).sim_seconds
            elapsed = time.perf_counter() - started
        if attempt:  # the first run warms imports and caches
            times.append(elapsed)
    return statistics.median(times), sim


def per_process(name: str) -> float:
    """Wall seconds of `carlos run` of the scenario in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.json"  # JSON is YAML
        path.write_text(json.dumps(manifest(name, True)))
        started = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "simcore.cli",
                "run",
                str(path),
                "-o",
                f"file://{tmp}/out",
                "-q",
                "-j",
                "1",
            ],
            check=True,
            capture_output=True,
            cwd=ROOT,
        )
        return time.perf_counter() - started


def baseline(name: str, steps: int) -> float:
    """libsumo alone: the same network, as many vehicles driven by SUMO, the same number of steps."""
    scenario = load_scenario(ROOT / "examples" / "scenarios" / f"{name}.xosc")
    assert scenario.road_file is not None
    network = prepare_network(scenario.road_file)
    import libsumo

    times = []
    for _ in range(REPEAT):
        world = SumoWorld(network, STEP, 0)
        try:
            edge = libsumo.edge.getIDList()[0]
            libsumo.route.add("r", [edge])
            for i, _entity in enumerate(scenario.entities):
                libsumo.vehicle.add(
                    f"v{i}", "r", departPos=str(20 + 30 * i), departSpeed="20", departLane="0"
                )
            started = time.perf_counter()
            for _ in range(steps):
                world.step()
            times.append(time.perf_counter() - started)
        finally:
            world.close()
    return statistics.median(times)


def main() -> None:
    rows = []
    MetricsAccumulator()  # imported for the warm-up of the module, not measured
    for name in SCENARIOS:
        wall, sim = warm(name, recording=True)
        wall_norec, _ = warm(name, recording=False)
        process = per_process(name)
        steps = round(sim / STEP)
        base = baseline(name, steps)
        rows.append(
            {
                "scenario": name,
                "simSeconds": round(sim, 2),
                "steps": steps,
                "warmWallSeconds": round(wall, 4),
                "warmSimPerWall": round(sim / wall, 1),
                "warmNoRecordingSimPerWall": round(sim / wall_norec, 1),
                "processWallSeconds": round(process, 3),
                "processSimPerWall": round(sim / process, 1),
                "sumoOnlySimPerWall": round(sim / base, 1),
                "ratioToSumoOnly": round(wall / base, 2),
            }
        )
    header = (
        f"{'scenario':<16}{'sim s':>7}{'steps':>7}{'warm s':>9}{'warm ×RT':>10}{'no-rec ×RT':>11}"
        f"{'process s':>11}{'proc ×RT':>10}{'SUMO ×RT':>10}{'÷SUMO':>8}"
    )
    print("simulated seconds per wall second (×RT = faster than real time), median of", REPEAT, "runs")
    print(header)
    print("-" * len(header))
    for r in rows:
        print(
            f"{r['scenario']:<16}{r['simSeconds']:>7}{r['steps']:>7}{r['warmWallSeconds']:>9}"
            f"{r['warmSimPerWall']:>10}{r['warmNoRecordingSimPerWall']:>11}{r['processWallSeconds']:>11}"
            f"{r['processSimPerWall']:>10}{r['sumoOnlySimPerWall']:>10}{r['ratioToSumoOnly']:>8}"
        )
    total_sim = sum(float(r["simSeconds"]) for r in rows)  # type: ignore[arg-type]
    total_warm = sum(float(r["warmWallSeconds"]) for r in rows)  # type: ignore[arg-type]
    figures = {
        "bench": "simcore",
        "stepSeconds": STEP,
        "repeat": REPEAT,
        "scenarios": rows,
        "warmSimPerWallOverall": round(total_sim / total_warm, 1),
    }
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
