"""esmini's controllers of the registry (simcore.scenario.controllers): ALKS_R157SM_Controller's four driver
models and SloppyDriverController. Plain tests of their semantics (need nothing), the esmini corpus's ALKS
scenarios against esmini's reference trajectories (skip without the corpus) and generated ALKS scenarios run
by both CARLOS and the esmini player (skip without it)."""

from __future__ import annotations

import itertools
import math
import random
from pathlib import Path

import pytest

from simcore import conformance
from simcore.errors import BadInput
from simcore.scenario import model as m
from simcore.scenario.controllers import rng_for
from simcore.scenario.controllers.road_view import (
    OVERLAP_FULL,
    OVERLAP_INSIDE,
    OVERLAP_INSIDE_AND_FULL,
    OVERLAP_NONE,
    OVERLAP_PART,
    overlapping_front,
)
from simcore.scenario.engine import ScenarioEngine
from simcore.scenario.motion import Body
from simcore.scenario.xosc import load_scenario
from simcore.world.opendrive import OpenDrive
from tests import differential_scenarios as gen
from tests.tooling import corpus_dir, esmini_player
from tests.xosc_fixtures import HIGHWAY, act, event, openscenario, scenario_object, sim_time, story, vehicle

STEP = 0.05


@pytest.fixture(scope="module")
def road() -> OpenDrive:
    return OpenDrive.from_file(HIGHWAY)


def alks(model: str, **properties: str) -> str:
    props = "".join(f'<Property name="{k}" value="{v}"/>' for k, v in {"model": model, **properties}.items())
    return (
        '<ObjectController><Controller name="ALKS_R157SM_Controller"><Properties>'
        f"{props}</Properties></Controller></ObjectController>"
    )


ACTIVATE_LONG = (
    "<PrivateAction><ControllerAction>"
    '<ActivateControllerAction longitudinal="true" lateral="false"/></ControllerAction></PrivateAction>'
)


def lane_change(lane: int, duration: float) -> str:
    return gen.lateral(
        "<LaneChangeAction>"
        f'<LaneChangeActionDynamics dynamicsShape="sinusoidal" value="{duration}" dynamicsDimension="time"/>'
        f'<LaneChangeTarget><AbsoluteTargetLane value="{lane}"/></LaneChangeTarget></LaneChangeAction>'
    )


def alks_scenario(
    kind: str,
    controller: str,
    *,
    ego_speed: float = 20.0,
    target_speed: float = 15.0,
    gap: float = 30.0,
    at: float = 2.0,
    duration: float = 3.0,
    rate: float = 6.0,
    seconds: float = 12.0,
) -> str:
    """Ego (the ALKS, lane -2 of the highway at s 50) and Target: `cutin` from lane -1 (`cutin_right`: from
    lane -3) `gap` m ahead at `at` s over `duration` s; `decelerate`: ahead in its lane, braking at `rate` from `at` s; `cutout`: ahead
    in its lane, leaving to lane -1 at `at` s, revealing a standing Third 60 m further."""
    ego = gen.private(
        "Ego", gen.teleport(gen.lane_position(50.0, -2)), gen.speed_to(ego_speed), ACTIVATE_LONG
    )
    target_lane = {"cutin": -1, "cutin_right": -3}.get(kind, -2)
    target = gen.private(
        "Target", gen.teleport(gen.lane_position(50.0 + gap, target_lane)), gen.speed_to(target_speed)
    )
    entities = scenario_object("Ego", vehicle(), controller) + scenario_object("Target")
    init = ego + target
    if kind in ("cutin", "cutin_right"):
        action = lane_change(-2, duration)
    elif kind == "decelerate":
        action = gen.speed_to(0.0, "linear", "rate", rate)
    else:
        action = lane_change(-1, duration)
        entities += scenario_object("Third")
        init += gen.private(
            "Third", gen.teleport(gen.lane_position(50.0 + gap + 60.0, -2)), gen.speed_to(0.0)
        )
    stories = story(act(event("Move", action, sim_time("greaterThan", at)), actor="Target"))
    return openscenario(
        entities=entities,
        init=init,
        stories=stories,
        stop=sim_time("greaterThan", seconds, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{HIGHWAY}"/></RoadNetwork>',
    )


def run(path: Path, road: OpenDrive, seconds: float, seed: int = 0) -> tuple[ScenarioEngine, list[float]]:
    engine = ScenarioEngine(load_scenario(path), road=road, sumo=None, step_seconds=STEP, seed=seed)
    speeds = []
    while engine.time < seconds - 1e-9 and not engine.ended:
        engine.advance()
        speeds.append(engine.bodies["Ego"].speed)
    return engine, speeds


def decelerations(speeds: list[float]) -> list[float]:
    return [(a - b) / STEP for a, b in itertools.pairwise(speeds)]


# --- ALKS_R157SM: plain tests ---------------------------------------------------------------------------------


def test_regulation_model_brakes_at_six_for_a_close_cut_in(tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(alks_scenario("cutin", alks("Regulation", cruise="false"), gap=30.0))
    engine, speeds = run(path, road, 8.0)
    decel = decelerations(speeds)
    assert max(decel) == pytest.approx(6.0)  # the regulation's deceleration, no more
    first = next(i for i, d in enumerate(decel) if d > 1.0)
    assert speeds[first - 1] == pytest.approx(20.0)  # held its speed until then (no cruise)
    assert engine.bodies["Ego"].speed < 15.0


def test_regulation_ignores_a_cut_in_far_enough_ahead(tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(alks_scenario("cutin", alks("Regulation", cruise="false"), gap=60.0, target_speed=19.0))
    _, speeds = run(path, road, 8.0)
    assert min(speeds) == pytest.approx(20.0)  # TTC stays above dv/12 + 0.45 s: no reaction


def test_reference_driver_perceives_reacts_then_brakes_with_its_jerk(tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(
        alks_scenario(
            "cutin", alks("ReferenceDriver", cruise="false", fullStop="true"), gap=30.0, target_speed=14.0
        )
    )
    engine, speeds = run(path, road, 10.0)
    decel = decelerations(speeds)
    first = next(i for i, d in enumerate(decel) if d > 0.0)
    # the lane change starts at 2 s: the 0.375 m wandering threshold, then 0.72 m more to perceive it, then
    # 0.75 s of reaction (at its speed: the reaction phase is not critical yet) before it brakes
    assert (first + 1) * STEP > 2.0 + 0.75
    jerk_step = 0.774 * 9.8 / 0.6 * STEP  # the reference driver's braking jerk, per step
    assert decel[first] == pytest.approx(jerk_step)
    assert max(decel) <= 0.85 * 9.8 + 1e-9  # its AEB's limit
    assert max(decel) > 0.774 * 9.8 - 1e-9  # it reaches full braking
    assert speeds[-1] == 0.0  # fullStop: to a standstill
    assert any("ALKS_R157SM_Controller activated" in line for line in engine.log)


def test_reference_driver_reacts_to_a_braking_vehicle_ahead(tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(
        alks_scenario(
            "decelerate", alks("ReferenceDriver", cruise="false"), gap=25.0, target_speed=20.0, rate=6.0
        )
    )
    engine, speeds = run(path, road, 10.0)
    assert min(speeds) < 5.0
    assert engine.bodies["Target"].s - engine.bodies["Ego"].s > 4.5


def test_an_unknown_model_is_bad_input_naming_the_property(tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(alks_scenario("cutin", alks("Careful")))
    with pytest.raises(BadInput, match=r"model .Careful.*Regulation, ReferenceDriver, RSS, FSM"):
        run(path, road, 1.0)


@pytest.mark.parametrize("model", ["RSS", "FSM"])
def test_rss_and_fsm_stop_behind_a_braking_vehicle(model: str, tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(alks_scenario("decelerate", alks(model), gap=40.0, target_speed=20.0, rate=4.0))
    engine, speeds = run(path, road, 15.0)
    assert min(speeds) < 5.0  # brakes hard (the target stands still from about 7 s)
    assert engine.bodies["Target"].s - engine.bodies["Ego"].s > 4.5


def _body(x: float, y: float, heading: float = 0.0) -> Body:
    box = m.Box(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)
    body = Body(
        entity=m.Entity(
            name="car", object_type="vehicle", category="car", box=box, performance=m.Performance()
        )
    )
    body.x, body.y, body.heading = x, y, heading
    return body


def test_overlapping_front_classifies_a_box_against_the_front_line() -> None:
    own = _body(0.0, 0.0)  # front line at x = 3.65, y from -0.9 to 0.9
    # the same width right ahead: inside, and within the tolerance of both ends
    assert overlapping_front(own, _body(10.0, 0.0), 0.1) == OVERLAP_INSIDE_AND_FULL
    assert overlapping_front(own, _body(10.0, 0.0), 0.0) == OVERLAP_INSIDE
    assert overlapping_front(own, _body(10.0, 1.0), 0.1) == OVERLAP_PART  # half across
    assert overlapping_front(own, _body(10.0, 5.0), 0.1) == OVERLAP_NONE  # a lane beside
    wide = _body(10.0, 0.0, math.pi / 2)  # across the lane: 4.5 m wide as seen from behind
    assert overlapping_front(own, wide, 0.1) == OVERLAP_FULL


# --- SloppyDriver ------------------------------------------------------------------------------------------


def sloppy_scenario(sloppiness: float, mode: str = "additive") -> str:
    controller = (
        '<ObjectController><Controller name="sloppy"><Properties>'
        '<Property name="esminiController" value="SloppyDriverController"/>'
        f'<Property name="sloppiness" value="{sloppiness}"/><Property name="mode" value="{mode}"/>'
        "</Properties></Controller></ObjectController>"
    )
    activate = (
        "<PrivateAction><ControllerAction>"
        '<ActivateControllerAction longitudinal="true" lateral="true"/></ControllerAction></PrivateAction>'
    )
    return openscenario(
        entities=scenario_object("Ego", vehicle(), controller),
        init=gen.private("Ego", gen.teleport(gen.lane_position(50.0, -2)), gen.speed_to(20.0), activate),
        stop=sim_time("greaterThan", 30.0, name="stop"),
        road=f'<RoadNetwork><LogicFile filepath="{HIGHWAY}"/></RoadNetwork>',
    )


def test_sloppy_driver_varies_speed_and_lane_position_within_its_bounds(
    tmp_path: Path, road: OpenDrive
) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(sloppy_scenario(0.6))
    engine, speeds = run(path, road, 30.0, seed=3)
    assert max(speeds) > 20.5 and min(speeds) < 19.5  # it does vary
    assert all(20.0 * (1 - 0.6 * 0.35) - 1e-9 <= v <= 20.0 * (1 + 0.6 * 0.35) + 1e-9 for v in speeds)
    ego = engine.bodies["Ego"]
    assert ego.lane_id == -2 or abs(ego.offset) < 3.5  # wanders within about a lane
    assert any("SloppyDriverController activated" in line for line in engine.log)


def test_sloppy_driver_is_the_same_for_a_seed_and_differs_between_seeds(
    tmp_path: Path, road: OpenDrive
) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(sloppy_scenario(0.6))
    a, speeds_a = run(path, road, 10.0, seed=3)
    b, speeds_b = run(path, road, 10.0, seed=3)
    _, speeds_c = run(path, road, 10.0, seed=4)
    assert speeds_a == speeds_b and (a.bodies["Ego"].x, a.bodies["Ego"].y) == (
        b.bodies["Ego"].x,
        b.bodies["Ego"].y,
    )
    assert speeds_a != speeds_c
    assert rng_for(3, "Ego").random() == rng_for(3, "Ego").random() != rng_for(3, "Other").random()


def test_without_sloppiness_the_sloppy_driver_drives_as_scripted(tmp_path: Path, road: OpenDrive) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(sloppy_scenario(0.0))
    engine, speeds = run(path, road, 10.0, seed=3)
    assert all(v == pytest.approx(20.0) for v in speeds)
    assert engine.bodies["Ego"].offset == pytest.approx(0.0, abs=1e-9)


def test_conformance_compares_entities_of_the_registry_controllers(tmp_path: Path) -> None:
    path = tmp_path / "s.xosc"
    path.write_text(alks_scenario("cutin", alks("Regulation")))
    assert conformance.uncompared_entities(load_scenario(path)) == set()
    path.write_text(sloppy_scenario(0.5))
    assert conformance.uncompared_entities(load_scenario(path)) == set()


# --- against esmini ------------------------------------------------------------------------------------------

ALKS_CORPUS = [
    "alks_r157_cut_in_quick_brake",
    "alks_cut-in",
    "alks_cut-out",
    "alks_decelerate",
    "alks_pedestrian",
]


def test_esmini_corpus_alks_scenarios_agree_with_esmini_reference() -> None:
    corpus = corpus_dir()
    files = [corpus / "resources" / "xosc" / f"{name}.xosc" for name in ALKS_CORPUS]
    results = conformance.run_files(files, reference_dir=corpus / "reference", cap_seconds=60.0)
    assert [Path(r.file).stem for r in results if not r.agreed] == []
    for r in results:
        ego = next(e for e in r.entities if e.name == "Ego")
        assert ego.scripted  # compared, not left out as controller-driven
        assert ego.rmse is not None and ego.rmse <= 0.5


KINDS = ("cutin", "cutin_right", "decelerate", "cutout")


def generated_alks(directory: Path, seed: int) -> list[Path]:
    """ALKS scenarios of every model and situation, their numbers drawn from `seed`."""
    rng = random.Random(seed)
    files = []
    models = [
        alks("Regulation"),
        alks("Regulation", cruise="false"),
        alks("ReferenceDriver", cruise="false", fullStop="true"),
        alks("ReferenceDriver", cutInPerceptionDelayMode="Time", aebTTC="1.2"),
        alks("ReferenceDriver", lateralTrigDistance="0.5", fullStop="true"),
        alks("RSS"),
        alks("FSM"),
    ]
    for i, (controller, kind) in enumerate(itertools.product(models, KINDS)):
        text = alks_scenario(
            kind,
            controller,
            ego_speed=round(rng.uniform(12, 25), 1),
            target_speed=round(rng.uniform(6, 18), 1),
            gap=round(rng.uniform(12, 40), 1),
            at=round(rng.uniform(1, 3), 1),
            duration=round(rng.uniform(2, 4), 1),
            rate=round(rng.uniform(3, 7), 1),
        )
        path = directory / f"alks_{i:02d}_{kind}.xosc"
        path.write_text(text)
        files.append(path)
    return files


def test_generated_alks_scenarios_agree_with_esmini(tmp_path: Path) -> None:
    esmini = esmini_player()
    files = generated_alks(tmp_path, seed=11)
    results = conformance.run_files(files, esmini=esmini, cap_seconds=30.0)
    disagreeing = [(Path(r.file).name, r.max_rmse, r.end_error, r.message) for r in results if not r.agreed]
    assert len(results) == len(files)
    # measured 2026-11-28: 28 of 28 agree with these draws (26/28 and 25/28 with seeds 23 and 37: a vehicle
    # braked for or passed one or two steps apart from esmini); one such difference is tolerated here
    assert len(disagreeing) <= 1, disagreeing
    assert all(rmse is not None and rmse < 1.5 for _, rmse, _, _ in disagreeing), disagreeing


# --- InteractiveController assigned during the run (headless: no key pressed) ------------------------------


def test_an_assigned_interactive_controller_on_the_lateral_domain_keeps_the_scripted_speed(
    tmp_path: Path, road: OpenDrive
) -> None:
    assign = (
        "<PrivateAction><ControllerAction><AssignControllerAction>"
        '<Controller name="interactiveDriver"><Properties>'
        '<Property name="esminiController" value="InteractiveController"/></Properties></Controller>'
        "</AssignControllerAction></ControllerAction></PrivateAction>"
    )
    activate = (
        "<PrivateAction><ControllerAction>"
        '<ActivateControllerAction longitudinal="false" lateral="true"/></ControllerAction></PrivateAction>'
    )
    events = event("Assign", assign, sim_time("greaterThan", 1.0)) + event(
        "Activate", activate, sim_time("greaterThan", 1.0)
    )
    path = tmp_path / "s.xosc"
    path.write_text(
        openscenario(
            entities=scenario_object("Ego"),
            init=gen.private("Ego", gen.teleport(gen.lane_position(50.0, -2)), gen.speed_to(15.0)),
            stories=story(act(events)),
            stop=sim_time("greaterThan", 6.0, name="stop"),
            road=f'<RoadNetwork><LogicFile filepath="{HIGHWAY}"/></RoadNetwork>',
        )
    )
    engine, speeds = run(path, road, 5.0)
    ego = engine.bodies["Ego"]
    assert ego.external  # the interactive controller drives it now
    assert speeds[-1] == pytest.approx(
        15.0
    )  # the default controller's speed: no engine brake on lateral only
    assert ego.s == pytest.approx(50.0 + 15.0 * 5.0, abs=0.2)  # it rolls on (it stood still before)
