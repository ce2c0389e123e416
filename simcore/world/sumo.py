"""SUMO as the traffic world: road networks converted with netconvert, vehicles simulated with libsumo.

Every scenario entity is a SUMO vehicle, so SUMO's drivers see it (leaders, gaps, collisions). Entities the
scenario moves are placed each step (`moveTo` while on their edge, `moveToXY` elsewhere); entities assigned the
SUMO driver (controller property `carlos.driver: sumo`) are moved by SUMO's car-following model and read back.

libsumo holds one simulation per process (a worker runs its runs one after another); libsumo is loaded
(`simcore.world.libsumo_api`) only here, when a run starts, never at operator import time.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import math
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final, NamedTuple

from simcore.errors import BadInput, SimulationError
from simcore.file_version import BoundedCache, ContentKey, content_key
from simcore.world import sumo_warm
from simcore.world.sumo_lanes import EdgeLanes, edge_lanes, nearest_lane

NETCONVERT_OPTIONS: Final = (
    "--output.original-names",  # keep OpenDRIVE road/lane ids on the SUMO edges and lanes
    "--no-turnarounds",
    "--offset.disable-normalization",  # SUMO x/y == OpenDRIVE x/y
    "--opendrive.import-all-lanes",
    "false",
)
NETCONVERT_TIMEOUT_S: Final = 300
#: moveToXY: a scripted vehicle whose front is this close to the centre line of a lane of its route is put on
#: that lane, matched against the route's lanes only (half the cost of a search of all lanes nearby; within a
#: driving lane of 4 m or less, its nearest lane centre is at most this far) ...
ON_ROUTE_MATCH_M: Final = 2.0
#: ... otherwise on the nearest lane within this distance (off the network beyond it), its route replaced
ANY_LANE_MATCH_M: Final = 50.0
#: SUMO's default deceleration of a passenger car (m/s²): what its driver uses when not in an emergency
COMFORT_DECELERATION: Final = 4.5


def sumo_home() -> Path:
    import sumo  # the eclipse-sumo wheel: binaries and data

    return Path(sumo.SUMO_HOME)


def default_cache_dir() -> Path:
    base = os.environ.get("CARLOS_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "carlos"
    )
    return Path(base) / "networks"


@functools.cache  # installed packages do not change under a running process (a worker asks once per run)
def sumo_version() -> str:
    from importlib.metadata import version

    return version("eclipse-sumo")


MAX_NETWORK_BYTES: Final = 512 * 1024 * 1024


def check_network_xml(path: Path) -> None:
    """A SUMO `.net.xml` is untrusted input too: streamed once through defusedxml (no DTD entities, no external
    references, bounded size, well-formed, root <net>) before SUMO reads it."""
    import xml.etree.ElementTree as ET

    import defusedxml.ElementTree as SafeET
    from defusedxml import DefusedXmlException

    size = path.stat().st_size
    if size > MAX_NETWORK_BYTES:
        raise BadInput(
            f"SUMO network is {size} bytes; at most {MAX_NETWORK_BYTES} are allowed", file=str(path)
        )
    root_tag = None
    try:
        for event, element in SafeET.iterparse(str(path), events=("start", "end")):
            if root_tag is None:
                root_tag = element.tag
            if event == "end":
                element.clear()
    except DefusedXmlException as exc:
        raise BadInput(
            f"SUMO network uses forbidden XML constructs ({type(exc).__name__})", file=str(path)
        ) from None
    except (ET.ParseError, LookupError) as exc:  # LookupError: an unknown encoding declared
        raise BadInput(f"SUMO network is not well-formed XML: {exc}", file=str(path)) from None
    if root_tag != "net":
        raise BadInput(f"root element is <{root_tag}>, expected <net> (a SUMO network)", file=str(path))


#: the `.net.xml` files check_network_xml passed, by content (a warm worker runs one network run after run)
_CHECKED_NETWORKS: Final[BoundedCache[ContentKey, bool]] = BoundedCache(64)
MAX_CACHED_FILES = 64


def _network_name(road_file: Path, data: bytes) -> str:
    """The SUMO network's file name for an OpenDRIVE file: its content (`data`), netconvert's options and
    SUMO's version hashed."""
    digest = hashlib.sha256()
    digest.update(data)
    digest.update(" ".join(NETCONVERT_OPTIONS).encode())
    digest.update(sumo_version().encode())
    return f"{road_file.stem}-{digest.hexdigest()[:16]}.net.xml"


def _read_road(road_file: Path) -> bytes:
    """The bytes of a road file (a SUMO network no larger than MAX_NETWORK_BYTES)."""
    try:
        if road_file.name.endswith(".net.xml"):
            size = road_file.stat().st_size
            if size > MAX_NETWORK_BYTES:
                raise BadInput(
                    f"SUMO network is {size} bytes; at most {MAX_NETWORK_BYTES} are allowed",
                    file=str(road_file),
                )
        return road_file.read_bytes()
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
        raise BadInput("road network file not found", file=str(road_file)) from None


def prepare_network(road_file: Path, cache_dir: Path | None = None) -> Path:
    """The SUMO network for an OpenDRIVE file (converted once, cached by content hash) or a `.net.xml`
    (checked once per content)."""
    data = _read_road(road_file)
    if road_file.name.endswith(".net.xml"):
        key = content_key(road_file, data)
        if key not in _CHECKED_NETWORKS:
            check_network_xml(road_file)
            _CHECKED_NETWORKS.put(key, True)
        return road_file
    if road_file.suffix != ".xodr":
        raise BadInput("road network must be OpenDRIVE (.xodr) or SUMO (.net.xml)", file=str(road_file))
    name = _network_name(road_file, data)
    cache_dir = cache_dir or default_cache_dir()
    target = cache_dir / name
    if target.is_file():
        return target
    cache_dir.mkdir(parents=True, exist_ok=True)
    netconvert = sumo_home() / "bin" / "netconvert"
    with tempfile.TemporaryDirectory(dir=cache_dir) as scratch:
        out = Path(scratch) / "net.xml"
        env = {**os.environ, "SUMO_HOME": str(sumo_home())}
        try:
            result = subprocess.run(
                [str(netconvert), "--opendrive-files", str(road_file), *NETCONVERT_OPTIONS, "-o", str(out)],
                capture_output=True,
                text=True,
                timeout=NETCONVERT_TIMEOUT_S,
                env=env,
                check=False,
            )
        except subprocess.TimeoutExpired:
            raise BadInput(
                f"netconvert took longer than {NETCONVERT_TIMEOUT_S} s", file=str(road_file)
            ) from None
        if result.returncode != 0 or not out.is_file():
            errors = [line for line in result.stderr.splitlines() if line.startswith("Error")]
            detail = "; ".join(errors[-3:]) or result.stderr.strip()[-300:]
            raise BadInput(f"netconvert could not convert the road network: {detail}", file=str(road_file))
        os.replace(out, target)  # atomic: parallel workers may race, both write the same content
    return target


#: Xerces-C++ 3.2's `XMLPlatformUtils::Initialize(locale, nlsHome, panicHandler, memoryManager)` (C++ name)
_XERCES_INITIALIZE: Final = (
    "_ZN11xercesc_3_216XMLPlatformUtils10InitializeEPKcS2_PNS_12PanicHandlerEPNS_13MemoryManagerE"
)


@functools.cache  # once per process
def keep_xml_parser_initialized(libsumo_library: str) -> bool:
    """Xerces-C++, the XML parser libsumo loads, initialised for the life of the process. libsumo initialises
    it at every start (`XMLPlatformUtils::Initialize`, building the parser's static tables: ~40% of a start)
    and terminates it at every close. Xerces counts these calls: only the first Initialize and the matching
    last Terminate do any work. One Initialize of our own, never terminated, lets every later start and close
    skip that work; what SUMO parses and simulates is the same. False (nothing done) when the library has no
    such function (another Xerces version in another SUMO wheel)."""
    try:
        # the loaded library's handle: the symbol is looked up in it and in the libraries it loaded
        initialize = getattr(ctypes.CDLL(libsumo_library), _XERCES_INITIALIZE)
    except (OSError, AttributeError):
        return False
    initialize.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_void_p, ctypes.c_void_p]
    initialize.restype = None
    initialize(b"en_US", None, None, None)  # the C++ default arguments (XMLUni::fgXercescDefaultLocale)
    return True


class SumoVehicleState(NamedTuple):
    """A SUMO-driven vehicle after a step (read every step: a tuple is the cheapest record)."""

    x: float  # reference point (rear axle), map frame
    y: float
    heading: float
    speed: float


#: SumoVehicleState((x, y, heading, speed)) without the Python-level __new__ of a NamedTuple (every step)
_vehicle_state: Final = functools.partial(tuple.__new__, SumoVehicleState)


def _sumo_angle(heading: float) -> float:
    """ENU heading (rad, CCW from +x) → SUMO angle (deg, clockwise from north)."""
    return (90.0 - math.degrees(heading)) % 360.0


def _heading(angle: float) -> float:
    return math.radians(90.0 - angle)


#: per network file content, each lane looked up so far → the lanes of its edge (None: a junction's lane): a
#: loaded network never changes, so a warm worker's runs on one network share them
_EDGES_OF_LANES: Final[BoundedCache[ContentKey, dict[str, EdgeLanes | None]]] = BoundedCache(MAX_CACHED_FILES)


def _network_key(network: Path) -> ContentKey | None:
    try:
        return content_key(network, network.read_bytes())
    except OSError:
        return None


def _edges_of_lanes(before: ContentKey | None, after: ContentKey | None) -> dict[str, EdgeLanes | None]:
    """The lanes known for a network whose file had the content `before` before SUMO loaded it and `after`
    after (the same: SUMO loaded that content); a map of this run's own otherwise."""
    if before is None or before != after:
        return {}
    return _EDGES_OF_LANES.get_or_make(before, dict)


class SumoWorld:
    """One libsumo simulation. Time advances only through `step()`."""

    def __init__(self, network: Path, step_seconds: float, seed: int, *, reuse: bool = True) -> None:
        """SUMO on `network` at time 0. `reuse`: the process's parked simulation when it was started the same
        way (simcore/world/sumo_warm.py), and parked again by `close()`; else started and closed."""
        from simcore.world import libsumo_api

        libsumo = libsumo_api.load()  # loads libsumo (~0.1 s): only where a run really starts
        _libsumo = libsumo_api.compiled()

        self._sumo: Any = libsumo
        # the calls of every step go to libsumo's SWIG functions, bound once: the `libsumo.vehicle` and
        # `libsumo.simulation` methods only forward to them (a Python call more each), and `simulationStep`
        # also runs traci's step listeners, which CARLOS never registers. Errors are the same
        # `libsumo.TraCIException`.
        self._simulation_step: Callable[[float], None] = _libsumo.simulation_step
        self._set_speed: Callable[[str, float], None] = _libsumo.vehicle_setSpeed
        self._move_to: Callable[[str, str, float], None] = _libsumo.vehicle_moveTo
        self._move_to_xy: Callable[..., None] = _libsumo.vehicle_moveToXY
        self._vehicle_ids: Callable[[], tuple[str, ...]] = _libsumo.vehicle_getIDList
        self._lane_id: Callable[[str], str] = _libsumo.vehicle_getLaneID
        self._position: Callable[[str, bool], tuple[float, float]] = _libsumo.vehicle_getPosition
        self._angle: Callable[[str], float] = _libsumo.vehicle_getAngle
        self._speed: Callable[[str], float] = _libsumo.vehicle_getSpeed
        self.step_seconds = step_seconds
        self._front: dict[str, float] = {}  # reference point → front bumper distance
        self._scripted: set[str] = set()
        # the speed last set for each scripted vehicle: SUMO keeps a set speed until it is set again (its speed
        # time line runs to the end of time), so the same speed is not set again
        self._speeds: dict[str, float] = {}
        # scripted vehicles: the place each is to have at the end of the next step (front x, y, heading,
        # speed), the lane it is on after the last step, and per lane the polyline segment it was on
        self._targets: dict[str, tuple[float, float, float, float]] = {}
        self._lane_of: dict[str, str] = {}
        self._hints: dict[str, dict[str, int]] = {}
        args = [
            "sumo",
            "-n",
            str(network),
            "--step-length",
            repr(step_seconds),
            "--begin",
            "0",
            "--no-step-log",
            "true",
            "--no-warnings",
            "true",
            "--collision.action",
            "none",  # CARLOS measures collisions itself; SUMO must not teleport or remove vehicles
            "--time-to-teleport",
            "-1",
            "--default.action-step-length",
            repr(step_seconds),
        ]
        keep_xml_parser_initialized(_libsumo.__file__)
        before = _network_key(network)
        # a parked simulation is reused for the same arguments on the same network content, whatever the seed
        # (`--seed` is added by sumo_warm.start)
        self._key: tuple[tuple[str, ...], ContentKey] | None = (
            (tuple(args), before) if reuse and before is not None else None
        )
        self._closed = False
        try:
            reused = sumo_warm.start(self._sumo, args, seed, self._key)
        except Exception as exc:  # libsumo raises its own TraCIException / FatalTraCIError
            raise SimulationError(f"SUMO did not start: {exc}") from exc
        self._edge_of_lane = _edges_of_lanes(before, before if reused else _network_key(network))

    def close(self) -> None:
        """The end of the run: SUMO parked for the next run when it may be reused, else closed. Once."""
        if not self._closed:
            self._closed = True
            sumo_warm.close(self._sumo, self._front, self._key)

    def __enter__(self) -> SumoWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- vehicles --------------------------------------------------------------------------------------

    def add_vehicle(
        self,
        name: str,
        *,
        length: float,
        width: float,
        height: float,
        front_offset: float,
        max_speed: float,
        max_accel: float,
        max_decel: float,
        x: float,
        y: float,
        heading: float,
        speed: float,
        scripted: bool,
        vclass: str = "passenger",
    ) -> None:
        """Insert a vehicle whose reference point is at (x, y). `front_offset`: reference point → front."""
        sumo = self._sumo
        vtype = f"carlos.{name}"
        sumo.vehicletype.copy("DEFAULT_VEHTYPE", vtype)
        sumo.vehicletype.setLength(vtype, max(length, 0.1))
        sumo.vehicletype.setWidth(vtype, max(width, 0.1))
        sumo.vehicletype.setHeight(vtype, max(height, 0.1))
        sumo.vehicletype.setMaxSpeed(vtype, max(max_speed, 0.1))
        sumo.vehicletype.setAccel(vtype, max(max_accel, 0.1))
        # the driver brakes comfortably (at most 4.5 m/s²) and uses the vehicle's full braking only in an emergency
        sumo.vehicletype.setDecel(vtype, max(min(COMFORT_DECELERATION, max_decel), 0.1))
        sumo.vehicletype.setEmergencyDecel(vtype, max(max_decel, 0.1))
        # deterministic driver; noise comes from the scenario. Also what lets a kept simulation leave its per-lane
        # random generators as they stand (simcore/world/sumo_warm.py): dawdling draws from them, times zero
        sumo.vehicletype.setImperfection(vtype, 0.0)
        sumo.vehicletype.setMinGap(vtype, 2.0)
        self._front[name] = front_offset
        fx, fy = x + front_offset * math.cos(heading), y + front_offset * math.sin(heading)
        edge, pos, lane_index = sumo.simulation.convertRoad(fx, fy, False, vclass)
        route_id = f"carlos.route.{name}"
        sumo.route.add(route_id, self._route_from(edge))
        sumo.vehicle.add(
            name,
            route_id,
            vtype,
            depart="now",
            departLane=str(lane_index),
            departPos=repr(max(pos, 0.0)),
            departSpeed=repr(max(speed, 0.0)),
        )
        sumo.vehicle.setLaneChangeMode(name, 0)  # lane changes come from the scenario only
        if scripted:
            self._scripted.add(name)
            sumo.vehicle.setSpeedMode(name, 0)  # the scenario's speed is taken as it is
        else:
            sumo.vehicle.setMaxSpeed(name, max(speed, 0.1))
        self.place(name, x, y, heading, speed)

    def _route_from(self, edge: str) -> list[str]:
        """The start edge and its straight-on successors, as far as the network goes (no cycles)."""
        sumo = self._sumo
        route = [edge]
        seen = {edge}
        current = edge
        for _ in range(500):
            nxt = None
            for lane_index in range(sumo.edge.getLaneNumber(current)):
                for link in sumo.lane.getLinks(f"{current}_{lane_index}"):
                    candidate = sumo.lane.getEdgeID(link[0])
                    if candidate not in seen and not candidate.startswith(":"):
                        nxt = candidate
                        break
                if nxt:
                    break
            if nxt is None:
                break
            route.append(nxt)
            seen.add(nxt)
            current = nxt
        return route

    def place(self, name: str, x: float, y: float, heading: float, speed: float) -> None:
        """Put a vehicle's reference point at (x, y) with heading and speed, for the next step: a scripted
        vehicle is there (and at that speed) when the step ends; a SUMO-driven one is reset there."""
        front = self._front[name]
        fx, fy = x + front * math.cos(heading), y + front * math.sin(heading)
        try:
            if name in self._scripted:
                speed = 0.0 if speed < 0.0 else speed  # max(speed, 0.0), without the builtin's call cost
                last = self._speeds.get(name)
                if (
                    last is None
                    or last != speed
                    or (speed == 0.0 and math.copysign(1.0, last) != math.copysign(1.0, speed))
                ):
                    self._set_speed(name, speed)
                    self._speeds[name] = speed
                self._targets[name] = (fx, fy, heading, speed)  # SUMO's angle only if SUMO searches
            else:
                self._move_xy(name, fx, fy, _sumo_angle(heading))
        except Exception as exc:
            raise SimulationError(f"SUMO could not place {name!r} at ({x:.2f}, {y:.2f}): {exc}") from exc

    def _move_xy(self, name: str, fx: float, fy: float, angle: float) -> None:
        """SUMO's own search for the place of a front bumper at (fx, fy); the vehicle is there at the end of
        the next step (remote control: it does not move by itself in that step)."""
        move = self._move_to_xy
        try:  # on a lane of its route: matched against the route's lanes only (half the cost)
            move(name, "", -1, fx, fy, angle, keepRoute=1, matchThreshold=ON_ROUTE_MATCH_M)
        except self._sumo.TraCIException:  # anywhere else: any lane nearby, and a new route
            move(name, "", -1, fx, fy, angle, keepRoute=2, matchThreshold=ANY_LANE_MATCH_M)

    def _spot_on_edge(self, name: str, fx: float, fy: float, speed: float) -> tuple[str, float] | None:
        """(lane, position) for a scripted vehicle's front at (fx, fy) found from where it was, while it stays
        on a lane of the edge it is on and clear of the edge's end (SUMO moves it by itself for a step before
        it is put there: it must not run off its edge meanwhile); None otherwise."""
        lane = self._lane_of.get(name)
        if not lane:
            return None
        edge = self._edge_of_lane[lane] if lane in self._edge_of_lane else self._edge_lanes(lane)
        if edge is None:
            return None
        hints = self._hints.setdefault(name, {})
        found = nearest_lane(edge.lanes, fx, fy, hints, edge.by_id[lane], edge.gaps)
        if found is None:
            return None
        shape, on = found
        if on.distance > ON_ROUTE_MATCH_M or on.pos + 2.0 * speed * self.step_seconds + 1.0 > shape.length:
            return None
        return shape.lane_id, on.pos

    def _edge_lanes(self, lane: str) -> EdgeLanes | None:
        """The lanes of the (normal) edge `lane` belongs to; None for a junction's internal lane."""
        sumo = self._sumo
        edge = sumo.lane.getEdgeID(lane)
        if edge.startswith(":"):
            self._edge_of_lane[lane] = None
            return None
        lanes = [f"{edge}_{i}" for i in range(sumo.edge.getLaneNumber(edge))]
        found = edge_lanes(tuple((lid, sumo.lane.getShape(lid), sumo.lane.getLength(lid)) for lid in lanes))
        for lid in lanes:
            self._edge_of_lane[lid] = found
        return found

    def has(self, name: str) -> bool:
        return name in self._front

    def set_desired_speed(self, name: str, speed: float) -> None:
        self._sumo.vehicle.setMaxSpeed(name, max(speed, 0.01))

    def change_lane(self, name: str, lane_index: int, duration: float) -> None:
        self._sumo.vehicle.changeLane(name, lane_index, max(duration, self.step_seconds))

    def lane_index_of(self, name: str) -> int:
        return int(self._sumo.vehicle.getLaneIndex(name))

    def step(self) -> None:
        """One SUMO step; afterwards each scripted vehicle is where it was last placed. One that stays on a
        lane of its edge is put there with `moveTo` after the step (as cheap as a step); any other is left
        to SUMO's `moveToXY` search before it."""
        after: list[tuple[str, str, float]] = []
        searched: list[str] = []
        try:
            for name, (fx, fy, heading, speed) in self._targets.items():
                spot = self._spot_on_edge(name, fx, fy, speed)
                if spot is None:
                    self._move_xy(name, fx, fy, _sumo_angle(heading))
                    searched.append(name)
                else:
                    after.append((name, *spot))
        except Exception as exc:
            raise SimulationError(f"SUMO could not place {name!r}: {exc}") from exc
        self._targets.clear()
        try:
            self._simulation_step(0.0)
            for name, lane, pos in after:
                self._move_to(name, lane, pos)
                self._lane_of[name] = lane
            for name in searched:
                self._hints.pop(name, None)
                try:
                    self._lane_of[name] = self._lane_id(name)
                except self._sumo.TraCIException:  # not in the network (yet): SUMO searches next time too
                    self._lane_of.pop(name, None)
        except Exception as exc:
            raise SimulationError(f"SUMO step failed: {exc}") from exc

    def read(self, name: str) -> SumoVehicleState | None:
        """A vehicle's pose and speed after the last step; None once it left the network (or before SUMO
        inserted it)."""
        if name not in self._vehicle_ids():
            return None
        fx, fy = self._position(name, False)
        heading = _heading(self._angle(name))
        front = self._front[name]
        return _vehicle_state(
            (fx - front * math.cos(heading), fy - front * math.sin(heading), heading, self._speed(name))
        )


def netconvert_available() -> bool:
    try:
        return (sumo_home() / "bin" / "netconvert").is_file() or shutil.which("netconvert") is not None
    except ImportError:
        return False
