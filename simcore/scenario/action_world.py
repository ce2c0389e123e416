"""What actions may read and change beyond `ScenarioWorld`: each entity's controller assignment and the
driver models running for it, trailers, the FollowGhost set-up, and the storyboard's clock state."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from simcore.scenario.world import ScenarioWorld

if TYPE_CHECKING:
    from simcore.scenario.controllers import EsminiController
    from simcore.scenario.drivers import AccDriver, NaturalDriver, OffroadFollower
    from simcore.scenario.ghost import Ghosts
    from simcore.scenario.motion import Body


class ActionWorld(ScenarioWorld, Protocol):
    # per entity: [driver of its assigned controller, active longitudinally, active laterally]
    controllers: dict[str, list[Any]]
    assigned_controller: dict[str, dict[str, str]]  # controller properties assigned during the run
    controller_slots: dict[
        str, dict[str, tuple[dict[str, str], set[str]]]
    ]  # per entity: controllers, domains
    acc_drivers: dict[str, AccDriver]
    natural_drivers: dict[str, NaturalDriver]
    vehicle_drivers: dict[str, OffroadFollower]
    esmini_controllers: dict[
        str, EsminiController
    ]  # controllers of the registry (simcore.scenario.controllers)
    seed: int  # the run's seed (controllers that draw random numbers)
    ghosts: Ghosts | None
    trailer_of: dict[str, str]  # tow vehicle → its trailer
    tow_of: dict[str, str]  # trailer → its tow vehicle
    ended_in_move: bool  # an action finished while moving its entity this step

    @property
    def started(self) -> bool:
        """The storyboard runs (Init is over)."""
        ...

    def align_trailers(self, tow: Body | None = None, *, pull: bool = False) -> None: ...
