"""V2X at scale: CAM/CPM/DENM generation and channel evaluation for N stations stepped at 10 Hz.

N vehicles (default 100) drive around a 1 km × 1 km block at 8-30 m/s, turning at its corners (so the CAM
heading, position and speed triggers all fire), one in ten braking hard now and then (DENMs); every tenth
vehicle also sends CPMs of what it perceives within 50 m. Every message goes through the channel model
(log-distance path loss, 4 dB shadowing, Rayleigh fading) to all other stations. One step = one frame.

Configurations (each `V2XService.step` on the same frames, messages delivered on an `InProcessBus`):
- "core": the rules and the channel only (CamTriggers + cams() builder + Channel.transmit), no service;
- "service": the full service, receivers' messages dropped by the subscriber;
- "service+los": the same with line-of-sight blocking by the entity boxes (slab tests, no road mesh);
- "service+cdr": the full service with a subscriber that takes every received copy's CDR bytes, as the recorder
  does (each message is serialised once, its copies share the bytes).

Times are CPU seconds of this process (`time.process_time`: the machine is shared, wall time would count the
other processes' turns), the best of BENCH_REPEAT (3) runs of each configuration. "× real time" = simulated seconds / CPU seconds of the whole step; "gen+chan ×" counts only the service's
generation and channel phases (message rules and builders, perception for CPMs, path loss, shadowing,
fading, line of sight, link records), leaving out the delivery of each received copy on its receiver's topic
and the metrics. The target is ≥ 20× for 100 stations at 10 Hz. Prints a table and, as its last line, one JSON
object with the figures and each configuration's ratio to the target.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simcore.spec import SimulationRunSpec  # noqa: E402
from simcore.transport.bus import InProcessBus, Message  # noqa: E402
from simcore.v2x import etsi  # noqa: E402
from simcore.v2x.channel import Channel, ChannelParameters  # noqa: E402
from simcore.v2x.service import V2XService  # noqa: E402
from simcore.v2x.triggers import CamTriggers  # noqa: E402
from simcore.world.state import BoundingBox, EntityState, WorldFrame  # noqa: E402

STATIONS = int(os.environ.get("BENCH_STATIONS", "100"))
REPEAT = int(os.environ.get("BENCH_REPEAT", "3"))
SECONDS = float(os.environ.get("BENCH_SECONDS", "20"))
STEP = 0.1
TARGET = 20.0
CAR = BoundingBox(1.4, 0.0, 0.75, 4.5, 1.8, 1.5)
SIDE = 1000.0


def _block_pose(d: float) -> tuple[float, float, float]:
    """Position and heading at distance d (m) around the block (counter-clockwise)."""
    d %= 4 * SIDE
    leg, along = int(d // SIDE), d % SIDE
    x, y = [(along, 0.0), (SIDE, along), (SIDE - along, SIDE), (0.0, SIDE - along)][leg]
    return x, y, leg * math.pi / 2


def frames() -> list[WorldFrame]:
    rng = np.random.default_rng(0)
    start = rng.uniform(0, 4 * SIDE, STATIONS)
    base = rng.uniform(8.0, 30.0, STATIONS)
    out = []
    dist = start.copy()
    speed = base.copy()
    for step in range(round(SECONDS / STEP) + 1):
        t = step * STEP
        accel = np.zeros(STATIONS)
        braking = (np.arange(STATIONS) % 10 == 0) & ((t % 8.0) < 1.5)
        accel[braking] = -6.0
        speed = np.where(braking, np.maximum(speed - 6.0 * STEP, 0.0), np.minimum(speed + 1.0 * STEP, base))
        dist = dist + speed * STEP
        entities = []
        for i in range(STATIONS):
            x, y, h = _block_pose(float(dist[i]))
            lane = 3.5 * (i % 3)
            entities.append(
                EntityState(
                    f"v{i}",
                    "vehicle",
                    "car",
                    x - lane * math.sin(h),
                    y + lane * math.cos(h),
                    0.0,
                    h,
                    0.0,
                    0.0,
                    float(speed[i]),
                    float(accel[i]),
                    0.0,
                    CAR,
                )
            )
        out.append(WorldFrame(step=step, time=round(t, 6), entities=tuple(entities), ego="v0"))
    return out


def spec(line_of_sight: bool) -> SimulationRunSpec:
    return SimulationRunSpec.model_validate(
        {
            "scenarios": [{"name": "b", "openscenario": "x.xosc"}],
            "simulation": {"stepSeconds": STEP},
            "v2x": {
                "stations": [{"entity": f"v{i}", "cpm": i % 10 == 0} for i in range(STATIONS)],
                "origin": {"latitude": 50.78, "longitude": 6.05},
                "channel": {"shadowingSigmaDb": 4.0, "fadingM": 1.0, "lineOfSight": line_of_sight},
            },
        }
    )


def run_service(frames_: list[WorldFrame], line_of_sight: bool, cdr: bool) -> tuple[float, dict[str, float]]:
    bus = InProcessBus()
    size = [0]

    def sink(message: Message) -> None:
        if cdr:  # as the recorder does: the message's CDR bytes (made once per message, shared by its copies)
            size[0] += len(message.cdr())

    bus.subscribe("*", sink)
    service = V2XService(spec(line_of_sight), bus, road=None, road_file=None, parameters={}, seed=1)
    started = time.process_time()
    for frame in frames_:
        service.step(frame)
    wall = time.process_time() - started
    metrics = service.metrics()
    metrics["cdrBytes"] = float(size[0])
    metrics.update({f"seconds.{k}": v for k, v in service.seconds.items()})
    return wall, metrics


def run_core(frames_: list[WorldFrame]) -> tuple[float, int]:
    triggers = CamTriggers(STATIONS)
    channel = Channel(ChannelParameters(shadowing_sigma_db=4.0, fading_m=1.0), seed=1)
    sent = 0
    started = time.process_time()
    for frame in frames_:
        pos = np.array([(e.x, e.y, 1.6) for e in frame.entities])
        heading = np.array([e.heading for e in frame.entities])
        speed = np.array([e.speed for e in frame.entities])
        due = triggers.step(frame.time, pos[:, :2], heading, speed)
        senders = np.flatnonzero(due.send)
        m = len(senders)
        zero = np.zeros(m)
        kin = etsi.KinematicsArrays(
            np.full(m, 50.78), np.full(m, 6.05), zero, zero, speed[senders], zero, zero, zero, zero
        )
        etsi.cams(
            (senders + 1).tolist(), [5] * m, frame.time, kin, due.low_frequency[senders].tolist(), [False] * m
        )
        if len(senders):
            channel.transmit(
                frame.step, STEP, pos[senders], pos, senders[:, None] == np.arange(STATIONS)[None, :]
            )
        sent += len(senders)
    return time.process_time() - started, sent


def best_service(frames_: list[WorldFrame], line_of_sight: bool, cdr: bool) -> tuple[float, dict[str, float]]:
    """The run with the least CPU time of REPEAT (each a new service on the same frames)."""
    runs = [run_service(frames_, line_of_sight, cdr) for _ in range(REPEAT)]
    return min(runs, key=lambda run: run[0])


def main() -> None:
    frames_ = frames()
    sim = frames_[-1].time
    rows: list[tuple[str, float, dict[str, Any]]] = []
    wall, cams = min((run_core(frames_) for _ in range(REPEAT)), key=lambda run: run[0])
    rows.append(("core", wall, {"v2x.messages.cam": float(cams)}))
    for name, los, cdr in (
        ("service", False, False),
        ("service+los", True, False),
        ("service+cdr", False, True),
    ):
        wall, metrics = best_service(frames_, los, cdr)
        rows.append((name, wall, metrics))
    print(f"{STATIONS} stations, {sim:g} s simulated at {1 / STEP:g} Hz, best of {REPEAT} runs")
    print(
        f"{'configuration':<14} {'CPU s':>8} {'× real time':>12} {'gen+chan ×':>11} {'CAM/s':>8} {'CPM/s':>7}"
        f" {'DENM/s':>7} {'links/s':>9}"
    )
    figures: dict[str, Any] = {
        "stations": STATIONS,
        "simSeconds": sim,
        "stepHz": 1 / STEP,
        "target": TARGET,
        "repeat": REPEAT,
    }
    for name, wall, m in rows:
        factor = sim / wall
        cam, cpm, denm = (m.get(f"v2x.messages.{k}", 0.0) / sim for k in ("cam", "cpm", "denm"))
        links = (cam + cpm + denm) * (STATIONS - 1)
        core = m.get("seconds.generate", 0.0) + m.get("seconds.channel", 0.0)
        core_factor = sim / core if core else factor
        print(
            f"{name:<14} {wall:8.2f} {factor:12.1f} {core_factor:11.1f} {cam:8.0f} {cpm:7.0f} {denm:7.0f} {links:9.0f}"
        )
        key = name.replace("+", "_")
        figures[key] = {
            "cpuSeconds": round(wall, 3),
            "realTimeFactor": round(factor, 2),
            "vsTarget": round(factor / TARGET, 3),
            "generationChannelRealTimeFactor": round(core_factor, 2),
            "generationChannelVsTarget": round(core_factor / TARGET, 3),
            "camPerSecond": round(cam, 1),
            "cpmPerSecond": round(cpm, 1),
            "denmPerSecond": round(denm, 1),
        }
        if "v2x.packetDeliveryRatio" in m:
            figures[key]["packetDeliveryRatio"] = round(m["v2x.packetDeliveryRatio"], 4)
        if m.get("cdrBytes"):
            figures[key]["cdrBytesPerSecond"] = round(m["cdrBytes"] / sim)
    print(json.dumps(figures, sort_keys=True))


if __name__ == "__main__":
    main()
