"""esmini's driver controllers as CARLOS runs them (simcore.scenario.actions.AccDriver): ACCController and
ALKSController on small synthetic scenarios — set speed, time gap kept to the vehicle ahead, override and
additive modes, activation and deactivation — and how conformance counts their entities."""

from __future__ import annotations

from pathlib import Path

import pytest

from simcore import conformance
from simcore.scenario import model as m
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests.xosc_fixtures import (
    HIGHWAY,
    act,
    event,
    openscenario,
    private_actions,
    road_network,
    scenario_object,
    sim_time,
    speed_action,
    story,
    teleport_lane,
)


def controller(kind: str, **properties: float | str) -> str:
    props = "".join(f'<Property name="{k}" value="{v}"/>' for k, v in properties.items())
    return f'<ObjectController><Controller name="{kind}"><Properties>{props}</Properties></Controller></ObjectController>'


def private(name: str, s: float, speed: float, lane: int = -2, extra: str = "") -> str:
    return private_actions(name, teleport_lane(s, lane), speed_action("step", "time", 0.0, speed), extra)


def activate(longitudinal: bool = True) -> str:
    flag = "true" if longitudinal else "false"
    return (
        f'<PrivateAction><ControllerAction><ActivateControllerAction longitudinal="{flag}" lateral="false"/>'
        "</ControllerAction></PrivateAction>"
    )


def highway_scenario(path: Path, entities: str, init: str, events: str = "") -> Path:
    """A scenario on the test highway: these entities and Init actions, events in one maneuver of Ego."""
    stories = story(act(events)) if events else ""
    path.write_text(openscenario(road=road_network(HIGHWAY), entities=entities, init=init, stories=stories))
    return path


def write(tmp_path: Path, ego_controller: str, init: str, events: str = "", *, target: bool = True) -> Path:
    entities = scenario_object("Ego", controller=ego_controller)
    if target:
        entities += scenario_object("Target")
    return highway_scenario(tmp_path / "acc.xosc", entities, init, events)


@pytest.fixture(scope="module")
def road() -> OpenDrive:
    return OpenDrive.from_file(HIGHWAY)


def run(path: Path, road: OpenDrive, seconds: float) -> tuple[ScenarioEngine, dict[float, float]]:
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=0.05)
    speeds = {}
    while engine.time < seconds - 1e-9:
        engine.advance()
        speeds[round(engine.time, 2)] = engine.bodies["Ego"].speed
    return engine, speeds


def gap(engine: ScenarioEngine) -> float:
    """Bumper to bumper, Ego's front to Target's rear (both boxes 4.5 m, centre 1.4 m ahead)."""
    ego, target = engine.bodies["Ego"], engine.bodies["Target"]
    return (target.s - ego.s) - (2.25 + 1.4) - (2.25 - 1.4)


@pytest.mark.parametrize("kind", ["ACCController", "ALKSController"])
@pytest.mark.parametrize("mode", ["override", "additive"])
def test_acc_follows_a_slower_vehicle_at_its_time_gap(
    tmp_path: Path, road: OpenDrive, kind: str, mode: str
) -> None:
    path = write(
        tmp_path,
        controller(kind, timeGap=1.0, mode=mode, setSpeed=30),
        private("Ego", 50, 30, extra=activate()) + private("Target", 150, 15),
    )
    assert not any("not modelled" in w for w in load_scenario(path).warnings)
    engine, speeds = run(path, road, 60.0)
    assert engine.acc_drivers["Ego"].lead == "Target"
    assert speeds[60.0] == pytest.approx(15.0, abs=0.05)
    # steady state: 3 m plus the time gap at the common speed, as the controller measures it (after the
    # others moved; in override mode before it moves its own entity by one step)
    moved = 15.0 * 0.05 if mode == "override" else 0.0
    assert gap(engine) == pytest.approx(3.0 + 1.0 * 15.0 - moved, abs=0.05)
    assert max(speeds.values()) <= 30.0 + 1e-9  # never above its set speed


def test_acc_on_a_free_road_reaches_its_set_speed_without_overshoot(tmp_path: Path, road: OpenDrive) -> None:
    path = write(
        tmp_path,
        controller("ACCController", mode="override", setSpeed=25),
        private("Ego", 50, 10, extra=activate()),
        target=False,
    )
    _, speeds = run(path, road, 20.0)
    # 0.7 · max acceleration per m/s of difference, at most 0.7 · 5 m/s²
    assert speeds[0.05] == pytest.approx(10 + 3.5 * 0.05)
    assert speeds[1.0] == pytest.approx(10 + 3.5 * 1.0)
    assert speeds[20.0] == pytest.approx(25.0, abs=1e-6)
    assert max(speeds.values()) <= 25.0 + 1e-9


def test_a_longer_time_gap_keeps_a_longer_distance(tmp_path: Path, road: OpenDrive) -> None:
    gaps = []
    for time_gap in (1.0, 2.0):
        path = write(
            tmp_path,
            controller("ACCController", timeGap=time_gap, mode="override", setSpeed=30),
            private("Ego", 50, 30, extra=activate()) + private("Target", 200, 20),
        )
        engine, _ = run(path, road, 60.0)
        gaps.append(gap(engine))
    assert gaps[0] == pytest.approx(3.0 + 20.0 - 1.0, abs=0.05)  # less one step of its own motion
    assert gaps[1] == pytest.approx(3.0 + 40.0 - 1.0, abs=0.05)


def test_override_mode_ignores_speed_actions_additive_mode_takes_them_as_set_speed(
    tmp_path: Path, road: OpenDrive
) -> None:
    slow_down = event("Slow", speed_action("step", "time", 0.0, 12.0), sim_time("greaterThan", 2.0))
    results = {}
    for mode in ("override", "additive"):
        path = write(
            tmp_path,
            controller("ACCController", mode=mode, setSpeed=20),
            private("Ego", 50, 20, extra=activate()),
            slow_down,
            target=False,
        )
        engine, speeds = run(path, road, 10.0)
        results[mode] = speeds[10.0]
        assert engine.acc_drivers["Ego"].set_speed == (20.0 if mode == "override" else 12.0)
    assert results["override"] == pytest.approx(20.0)
    assert results["additive"] == pytest.approx(12.0)


def test_without_set_speed_the_speed_at_activation_is_the_set_speed(tmp_path: Path, road: OpenDrive) -> None:
    path = write(
        tmp_path,
        controller("ACCController", mode="override"),
        private("Ego", 50, 17, extra=activate()),
        target=False,
    )
    engine, speeds = run(path, road, 5.0)
    assert engine.acc_drivers["Ego"].set_speed == 17.0
    assert speeds[5.0] == pytest.approx(17.0)


def test_activation_and_deactivation(tmp_path: Path, road: OpenDrive) -> None:
    """Not active before its ActivateControllerAction (the entity keeps its speed toward the slower vehicle),
    active from it (it slows down to follow), inactive again after the deactivation (it keeps its speed)."""
    on = event("On", activate(True), sim_time("greaterThan", 2.0))
    off = event("Off", activate(False), sim_time("greaterThan", 30.0))
    path = write(
        tmp_path,
        controller("ACCController", mode="override", timeGap=1.0),
        private("Ego", 50, 25) + private("Target", 200, 10),
        on + off,
    )
    engine, speeds = run(path, road, 34.0)
    assert speeds[2.0] == pytest.approx(25.0)  # not active yet
    assert speeds[29.0] == pytest.approx(10.0, abs=0.1)  # following
    assert "Ego" not in engine.acc_drivers
    assert speeds[34.0] == pytest.approx(speeds[31.0])  # inactive: the speed stays
    assert any("ACC controller activated" in line for line in engine.log)
    assert any("ACC controller deactivated" in line for line in engine.log)


def test_a_vehicle_in_another_lane_is_not_followed(tmp_path: Path, road: OpenDrive) -> None:
    path = write(
        tmp_path,
        controller("ACCController", mode="override", setSpeed=30),
        private("Ego", 50, 30, extra=activate()) + private("Target", 80, 10, lane=-3),
    )
    engine, speeds = run(path, road, 10.0)
    assert engine.acc_drivers["Ego"].lead is None
    assert min(speeds.values()) == pytest.approx(30.0)


def test_conformance_compares_entities_of_modelled_controllers_only(tmp_path: Path) -> None:
    acc = write(
        tmp_path,
        controller("ACCController", mode="override"),
        private("Ego", 50, 20, extra=activate()),
        target=False,
    )
    assert conformance.uncompared_entities(load_scenario(acc)) == set()
    sloppy = acc.with_name("sloppy.xosc")
    sloppy.write_text(
        acc.read_text().replace('Controller name="ACCController"', 'Controller name="SloppyDriver"')
    )
    assert conformance.uncompared_entities(load_scenario(sloppy)) == {"Ego"}
    kinds = m.controller_kinds(load_scenario(sloppy))
    assert kinds == {"Ego": {"SloppyDriver"}}
