"""The read/write view of a running scenario that conditions, actions and drivers use (never the engine's
own attributes): the entities and their state, the clock, the road network and position queries, the
parameter and signal stores, and the two ways out to the world (the log and the warnings).

`ScenarioEngine` is the one implementation; tests may pass any object with these members.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    from simcore.scenario import model as m
    from simcore.scenario.measure import Measure
    from simcore.scenario.motion import Body
    from simcore.scenario.signals import SignalControllers
    from simcore.scenario.storyboard import Registry
    from simcore.world.opendrive import OpenDrive
    from simcore.world.state import EntityState

Pose = tuple[float, float, float, float]  # world x, y, z, heading


class ScenarioWorld(Protocol):
    """Entities, clock, road and stores of one scenario run."""

    source: str  # the scenario file (for messages)
    road: OpenDrive | None
    time: float
    dt: float
    step_index: int
    bodies: dict[str, Body]
    measure: Measure
    registry: Registry  # the storyboard's elements by kind and name
    log: list[str]
    warnings: list[str]
    parameter_values: dict[str, Any]
    variables: dict[str, Any]
    signals: dict[str, str]  # traffic signal (id or name) → the state it shows
    signal_phases: dict[str, str]  # signal controller → its current phase
    signal_control: SignalControllers
    memo: dict[tuple[str, int], Any]  # per-run memory of conditions and positions, by (kind, id of element)

    def body(self, name: str) -> Body:
        """The entity `name` ("$owner": the actor of the action running now); BadInput when undeclared."""
        ...

    def state_of(self, body: Body) -> EntityState: ...

    def moved(self) -> None:
        """Bodies moved (or left the world): per-step caches of their states and measurements are stale."""
        ...

    def resolve_position(self, position: m.Position, for_body: Body | None = None) -> Pose: ...

    def place(self, body: Body, position: m.Position) -> None:
        """Teleport `body` to `position`."""
        ...

    def locate(self, body: Body) -> None:
        """Road coordinates of a body moved in world coordinates."""
        ...

    def track_road(self, body: Body, lock_lane: bool = False) -> None:
        """Road coordinates of a body moved freely (a trajectory)."""
        ...

    def shift_along(self, body: Body, distance: float) -> None: ...

    def distance_to(self, body: Body, target: Pose) -> float:
        """Distance still to travel to a pose: along the road when both are on the same road."""
        ...

    def plan_route(self, body: Body, targets: list[m.Position]) -> list[tuple[str, int]]: ...

    def sumo_set_speed(self, body: Body, speed: float) -> None: ...

    def sumo_change_lane(self, body: Body, lane_id: int, duration: float) -> None: ...


class GhostWorld(ScenarioWorld, Protocol):
    """The world a FollowGhostController runs in (simcore/scenario/ghost.py): it can also run the ghost ahead
    alone, sampling its trail."""

    def run_alone(self, body: Body, dt: float, steps: int, sample: Callable[[int], None]) -> None: ...
