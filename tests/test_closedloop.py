"""Closed loop: the bicycle model, the control commands, external controllers in scenarios, lockstep with an
in-process node and with a controller in its own process (loopback topic hub), and what a dead controller
does to the run."""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest
import yaml

from simcore.closedloop import ACKERMANN, TWIST, BicycleState, Command, Vehicle, bicycle_step, command_from
from simcore.errors import SimulationError
from simcore.manifest import parse_manifest
from simcore.pipeline import simulate
from simcore.plan import Plan
from simcore.transport.bus import InProcessBus, Message
from simcore.transport.messages import TYPESTORE
from tests.xosc_fixtures import (
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
    vehicle,
    write_scenario,
)

ROOT = Path(__file__).resolve().parents[1]
CUT_IN = ROOT / "examples" / "scenarios" / "cut-in.xosc"
CAR = Vehicle(wheelbase=2.8, max_steering=0.5, max_speed=50.0, max_acceleration=3.0, max_deceleration=8.0)
T = TYPESTORE.types


# --- the model -------------------------------------------------------------------------------------------


def test_constant_steering_drives_a_circle_of_the_bicycle_radius() -> None:
    state = BicycleState(0.0, 0.0, 0.0, 10.0, 0.2)
    command = Command(speed=10.0, steering_angle=0.2)
    points = []
    for _ in range(400):
        state = bicycle_step(state, command, CAR, 0.05)
        points.append((state.x, state.y))
    radius = CAR.wheelbase / math.tan(0.2)
    centre = (0.0, radius)  # turning left from the origin heading +x
    for x, y in points:
        assert math.hypot(x - centre[0], y - centre[1]) == pytest.approx(radius, abs=1e-6)
    assert state.speed == pytest.approx(10.0)


def test_speed_follows_the_commanded_acceleration_within_the_vehicle_limits() -> None:
    state = BicycleState(0.0, 0.0, 0.0, 0.0)
    for _ in range(20):  # 1 s at 2 m/s² asked
        state = bicycle_step(state, Command(speed=30.0, acceleration=2.0), CAR, 0.05)
    assert state.speed == pytest.approx(2.0)
    assert state.x == pytest.approx(1.0)  # ½ a t²
    for _ in range(20):  # 0: the vehicle's maximum acceleration (3 m/s²)
        state = bicycle_step(state, Command(speed=30.0), CAR, 0.05)
    assert state.speed == pytest.approx(5.0)
    for _ in range(40):  # braking to a stop at 8 m/s² (max deceleration), not beyond
        state = bicycle_step(state, Command(speed=0.0, acceleration=20.0), CAR, 0.05)
    assert state.speed == 0.0
    steer = bicycle_step(state, Command(speed=0.0, steering_angle=1.5), CAR, 0.05)
    assert steer.steering == pytest.approx(0.5)  # the axle's maxSteering


def test_twist_commands_the_yaw_rate() -> None:
    state = BicycleState(0.0, 0.0, 0.0, 5.0)
    for _ in range(20):
        state = bicycle_step(state, Command(speed=5.0, steering_angle=None, yaw_rate=0.5), CAR, 0.05)
    assert state.heading == pytest.approx(0.5)
    assert math.hypot(state.x, state.y) == pytest.approx(2 * (5.0 / 0.5) * math.sin(0.25))


def _ackermann(stamp_s: float, speed: float, steering: float) -> Any:
    ns = round(stamp_s * 1e9)
    return T["ackermann_msgs/msg/AckermannDriveStamped"](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""
        ),
        drive=T["ackermann_msgs/msg/AckermannDrive"](
            steering_angle=steering, steering_angle_velocity=0.0, speed=speed, acceleration=0.0, jerk=0.0
        ),
    )


def test_commands_from_ackermann_and_twist_messages_and_cdr() -> None:
    message = Message("/carlos/Ego/control", ACKERMANN, 1.5, msg=_ackermann(1.5, 12.0, -0.1))
    wire = Message("/carlos/Ego/control", ACKERMANN, 1.5, data=message.cdr())  # as from another process
    command = command_from(wire, 7)
    assert (command.stamp, command.speed, command.sequence) == (1.5, 12.0, 7)
    assert command.steering_angle == pytest.approx(-0.1)
    vector = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](
        linear=vector(x=3.0, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.2)
    )
    command = command_from(Message("/carlos/Ego/control", TWIST, 0.0, msg=twist), 2)
    assert (command.speed, command.yaw_rate, command.steering_angle, command.stamp) == (3.0, 0.2, None, None)
    odometry = Message(
        "/carlos/Ego/control", "std_msgs/msg/String", 0.0, msg=T["std_msgs/msg/String"](data="x")
    )
    with pytest.raises(ValueError, match="AckermannDriveStamped"):
        command_from(odometry, 0)


# --- external controllers in a scenario -------------------------------------------------------------------


def _scenario(tmp_path: Path, controller: str, activate: str, assign_later: str = "") -> Path:
    """A straight road; Ego with `controller` in its ObjectController, Init: lane position, 20 m/s and the
    `activate` actions; an event at t=2 s with the `assign_later` action."""
    road = textwrap.dedent(
        """\
        <?xml version="1.0"?>
        <OpenDRIVE><header revMajor="1" revMinor="6" name="straight"/>
          <road id="1" junction="-1" length="1000">
            <planView><geometry s="0" x="0" y="0" hdg="0" length="1000"><line/></geometry></planView>
            <lanes><laneSection s="0">
              <center><lane id="0" type="none"/></center>
              <right><lane id="-1" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
            </laneSection></lanes>
          </road>
        </OpenDRIVE>
        """
    )
    (tmp_path / "straight.xodr").write_text(road)
    stories = ""
    if assign_later:
        later = event(
            "E",
            f"<PrivateAction>{assign_later}</PrivateAction>",
            sim_time("greaterThan", 2, name="c"),
            "overwrite",
        )
        stories = story(act(later, start=sim_time("greaterThan", 0, name="go")))
    ego = vehicle(max_speed=50, max_acceleration=3, max_deceleration=8)
    speed = speed_action("step", "time", 0, 20)
    xosc = openscenario(
        description="closed loop",
        road=road_network("straight.xodr"),
        entities=scenario_object("Ego", ego, controller),
        init=private_actions("Ego", teleport_lane(10, lane=-1), activate, speed),
        stories=stories,
        stop=sim_time("greaterThan", 4, name="end"),
    )
    return write_scenario(tmp_path, xosc, "closed.xosc")


EXTERNAL = """<ObjectController><Controller name="ext"><Properties>
  <Property name="carlos.driver" value="external"/></Properties></Controller></ObjectController>"""
ESMINI_EXTERNAL = """<ObjectController><Controller name="ext"><Properties>
  <Property name="esminiController" value="ExternalController"/></Properties></Controller></ObjectController>"""
ACTIVATE = '<PrivateAction><ActivateControllerAction longitudinal="true" lateral="true"/></PrivateAction>'
DEACTIVATE = (
    '<ControllerAction><ActivateControllerAction longitudinal="false" lateral="false"/></ControllerAction>'
)


def _engine(path: Path, external: Any = None) -> Any:
    from simcore.scenario.engine import ScenarioEngine
    from simcore.scenario.xosc import load_scenario
    from simcore.world.opendrive import OpenDrive

    scenario = load_scenario(path, {})
    road = OpenDrive.from_file(path.parent / "straight.xodr")
    return ScenarioEngine(scenario, road=road, sumo=None, step_seconds=0.05, external=external)


def _xs(engine: Any) -> list[tuple[float, float, float]]:
    out = []
    while not engine.ended:
        frame = engine.step()
        ego = frame.entities[0]
        out.append((frame.time, ego.x, ego.speed))
    return out


@pytest.mark.parametrize("controller", [EXTERNAL, ESMINI_EXTERNAL])
def test_an_active_external_controller_without_input_holds_the_entity_as_esmini_does(
    tmp_path: Path, controller: str
) -> None:
    trace = _xs(_engine(_scenario(tmp_path, controller, ACTIVATE)))
    assert {x for _, x, _ in trace} == {10.0}  # the Init speed action is overridden by the controller
    assert {v for _, _, v in trace} == {0.0}


def test_an_external_controller_moves_the_entity_only_while_active(tmp_path: Path) -> None:
    # assigned but never activated: the scenario's actions move it
    trace = _xs(_engine(_scenario(tmp_path, EXTERNAL, "")))
    assert trace[-1][1] == pytest.approx(10.0 + 20.0 * trace[-1][0], abs=1e-6)
    # activated at the start, deactivated at t=2 s: stands, then the default controller drives it again
    # (from standstill: the Init speed was never applied)
    engine = _engine(_scenario(tmp_path, EXTERNAL, ACTIVATE, assign_later=DEACTIVATE))
    trace = _xs(engine)
    assert all(x == 10.0 for t, x, _ in trace if t <= 2.0)
    assert any("deactivated" in line for line in engine.log)


def test_carlos_driver_must_be_a_known_value(tmp_path: Path) -> None:
    from simcore.errors import BadInput

    bad = EXTERNAL.replace('value="external"', 'value="autopilot"')
    with pytest.raises(BadInput, match=r"carlos\.driver='autopilot'.*scenario, sumo or external"):
        _engine(_scenario(tmp_path, bad, ACTIVATE))


# --- the loop through the runner ------------------------------------------------------------------------


def _run(
    tmp_path: Path, control: dict[str, Any] | None, sut: dict[str, Any] | None = None, **extra: Any
) -> Any:
    spec: dict[str, Any] = {
        "scenarios": [{"name": "cut-in", "openscenario": str(CUT_IN)}],
        "simulation": {"stepSeconds": 0.05, "maxSeconds": 6},
        "recording": {"enabled": False},
        **extra,
    }
    if control is not None:
        spec["control"] = control
    if sut is not None:
        spec["systemUnderTest"] = sut
    return parse_manifest(
        {
            "apiVersion": "carlos.dev/v1alpha1",
            "kind": "SimulationRun",
            "metadata": {"name": "loop"},
            "spec": spec,
        },
        source="test",
    )


def _odometry(bus: InProcessBus, entity: str = "Ego") -> list[tuple[float, float, float, float]]:
    seen: list[tuple[float, float, float, float]] = []

    def on(message: Message) -> None:
        odom = message.obj()
        p = odom.pose.pose.position
        seen.append((message.time_s, p.x, p.y, odom.twist.twist.linear.x))

    bus.subscribe(f"/carlos/{entity}/odometry", on)
    return seen


def test_lockstep_with_an_in_process_controller_follows_its_commands(tmp_path: Path) -> None:
    run = _run(
        tmp_path,
        {"entities": ["Ego"], "timeoutSeconds": 5},
        {
            "module": "examples.controller:CruiseController",
            "pythonPath": [str(ROOT)],
            "parameters": {"speed": 30.0, "acceleration": 1.0},
        },
    )
    bus = InProcessBus()
    seen = _odometry(bus)
    simulate(run, Plan(run.spec)[0], CUT_IN, tmp_path, bus=bus, base_dir=tmp_path)
    times = [t for t, *_ in seen]
    assert times[0] == 0.0 and times[-1] == pytest.approx(6.0)
    # SUMO would hold Ego near 25 m/s; the controller asks 30 m/s at 1 m/s²: +1 m/s each second
    start_speed = seen[0][3]
    for t, _, _, v in seen:
        assert v == pytest.approx(min(30.0, start_speed + t), abs=1e-6)
    # it holds its lane: the lateral position does not drift
    assert max(abs(y - seen[0][2]) for _, _, y, _ in seen) < 0.05


def test_lockstep_without_any_controller_fails_clearly_after_the_timeout(tmp_path: Path) -> None:
    run = _run(tmp_path, {"entities": ["Ego"], "timeoutSeconds": 0.5, "startupTimeoutSeconds": 0.5})
    bus = InProcessBus()
    bus.subscribe("/carlos/Ego/odometry", lambda m: None)  # someone listens, nobody answers
    with pytest.raises(
        SimulationError, match=r"no command on /carlos/Ego/control answering t=0.00 s within 0.5 s"
    ):
        simulate(run, Plan(run.spec)[0], CUT_IN, tmp_path, bus=bus, base_dir=tmp_path)
    with pytest.raises(SimulationError, match=r"no node subscribed to /carlos/Ego/odometry"):
        simulate(run, Plan(run.spec)[0], CUT_IN, tmp_path, bus=InProcessBus(), base_dir=tmp_path)


def test_control_entities_must_exist(tmp_path: Path) -> None:
    from simcore.errors import BadInput

    run = _run(tmp_path, {"entities": ["Nobody"], "mode": "freeRunning"})
    with pytest.raises(BadInput, match=r"spec\.control\.entities.*'Nobody' is not in the scenario"):
        simulate(run, Plan(run.spec)[0], CUT_IN, tmp_path, bus=InProcessBus(), base_dir=tmp_path)


# --- a controller in its own process --------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _manifest(tmp_path: Path, timeout: float) -> Path:
    body = {
        "apiVersion": "carlos.dev/v1alpha1",
        "kind": "SimulationRun",
        "metadata": {"name": "remote"},
        "spec": {
            "scenarios": [{"name": "cut-in", "openscenario": str(CUT_IN)}],
            "simulation": {"stepSeconds": 0.05, "maxSeconds": 5},
            "control": {"entities": ["Ego"], "timeoutSeconds": timeout, "startupTimeoutSeconds": 30},
            "execution": {"retries": 0},
            "output": {"url": f"file://{tmp_path / 'results'}"},
        },
    }
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(body))
    return path


def _processes(
    tmp_path: Path,
    timeout: float,
    stop_after: int | None,
    transport: str = "loopback",
    extra_env: dict[str, str] | None = None,
) -> tuple[subprocess.Popen[str], subprocess.Popen[str]]:
    """`carlos run --transport …` and the example controller as a process of its own (loopback: on a free
    port; dds: the domain and config of `extra_env`)."""
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), **(extra_env or {})}
    where = ["--bus-port", str(port)] if transport == "loopback" else []
    carlos = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "simcore.cli",
            "run",
            str(_manifest(tmp_path, timeout)),
            "--transport",
            transport,
            *where,
            "-q",
        ],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    args = [
        sys.executable,
        "-m",
        "examples.controller",
        "--transport",
        transport,
        *(["--port", str(port)] if transport == "loopback" else []),
        "--speed",
        "15",
        "--acceleration",
        "2",
    ]
    if stop_after is not None:
        args += ["--stop-after", str(stop_after)]
    controller = subprocess.Popen(
        args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    return carlos, controller


def test_a_controller_process_drives_the_ego_in_lockstep_over_the_loopback_hub(tmp_path: Path) -> None:
    carlos, controller = _processes(tmp_path, timeout=20, stop_after=None)
    check_the_controller_drove_the_ego(tmp_path, carlos, controller)


def check_the_controller_drove_the_ego(
    tmp_path: Path, carlos: subprocess.Popen[str], controller: subprocess.Popen[str]
) -> None:
    """The run passed in lockstep with the controller answering all 101 frames, its commands are recorded
    at the times of the frames they answer, and the ego followed them."""
    from rosbags.highlevel import AnyReader

    out, _ = carlos.communicate(timeout=120)
    ctl_out, _ = controller.communicate(timeout=30)
    assert carlos.returncode == 0, out
    assert controller.returncode == 0, ctl_out
    assert "end of run after 101 commands" in ctl_out  # frames at 0, 0.05, …, 5.0 s
    summary = json.loads((tmp_path / "results" / "remote" / "0" / "summary.json").read_text())
    assert summary["status"] == "passed"
    # the recording holds the commands next to the odometry they answer, and the ego followed them:
    # from its Init speed down to 15 m/s at 2 m/s²
    speeds: dict[float, float] = {}
    commands: set[float] = set()
    with AnyReader(
        [tmp_path / "results" / "remote" / "0" / "recording.mcap"], default_typestore=TYPESTORE
    ) as reader:
        wanted = [c for c in reader.connections if c.topic in ("/carlos/Ego/odometry", "/carlos/Ego/control")]
        for connection, stamp, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == "/carlos/Ego/control":
                commands.add(round(stamp / 1e9, 3))
                assert msg.drive.speed == 15.0
            else:
                speeds[round(stamp / 1e9, 3)] = msg.twist.twist.linear.x
    # every frame's command is recorded but maybe the last one's (the run ends without waiting for it)
    assert set(speeds) - {max(speeds)} <= commands <= set(speeds)
    v0 = speeds[0.0]
    assert v0 > 15.0
    for t, v in speeds.items():
        assert v == pytest.approx(max(15.0, v0 - 2.0 * t), abs=1e-4)


def test_killing_the_controller_fails_the_run_with_a_clear_message(tmp_path: Path) -> None:
    carlos, controller = _processes(tmp_path, timeout=1.0, stop_after=20)
    check_the_dead_controller_failed_the_run(tmp_path, carlos, controller)


def check_the_dead_controller_failed_the_run(
    tmp_path: Path, carlos: subprocess.Popen[str], controller: subprocess.Popen[str]
) -> None:
    ctl_out, _ = controller.communicate(timeout=60)
    assert controller.returncode == 1 and "dying after 20 commands" in ctl_out
    out, _ = carlos.communicate(timeout=120)
    assert carlos.returncode == 3, out
    summary = json.loads((tmp_path / "results" / "remote" / "0" / "summary.json").read_text())
    assert summary["status"] == "error"
    assert "no command on /carlos/Ego/control answering t=1.00 s within 1 s" in summary["error"]
    assert "no command on /carlos/Ego/control answering t=1.00 s" in out  # said on the console too
