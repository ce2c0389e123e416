"""esmini's controllers CARLOS runs as esmini does, one module each, and the registry that maps a controller's
kind (its `esminiController` property, else its name) to the module's controller.

Every controller here is stepped after every entity has moved in the step (as esmini steps controllers after
the default motion), sets its entity's speed, and moves it with that speed (the engine skips the entity's
default motion for it); it acts only on the domains it is active on and operates (`domains`).
The controllers of `simcore.scenario.drivers` (ACC/ALKS, NaturalDriver, OffroadFollower) and the
FollowGhost controller (`simcore.scenario.ghost`) predate this registry and keep their own wiring."""

from __future__ import annotations

import hashlib
import random
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from simcore.scenario.motion import Body
    from simcore.scenario.world import ScenarioWorld


class EsminiController(Protocol):
    """One controller on one entity."""

    actor: Body
    domains: frozenset[str]  # the domains it is active on

    @property
    def moves_itself(self) -> bool:
        """It moves its entity (the engine skips the entity's default motion)."""
        ...

    def step(self, dt: float) -> None: ...


# controller kind → the domains it operates on (esmini's operating domains)
OPERATING_DOMAINS: dict[str, frozenset[str]] = {
    "ALKS_R157SM_Controller": frozenset({"longitudinal"}),
    "SloppyDriverController": frozenset({"longitudinal", "lateral"}),
    "FollowRouteController": frozenset({"longitudinal", "lateral"}),
    "LoomingController": frozenset({"longitudinal"}),
}
KINDS = frozenset(OPERATING_DOMAINS)  # simcore.scenario.model.REGISTERED_CONTROLLERS names the same


def rng_for(seed: int, entity: str) -> random.Random:
    """The random numbers of one entity's controller: from the run's seed and the entity's name only."""
    digest = hashlib.sha256(f"{seed}:{entity}".encode()).digest()
    return random.Random(int.from_bytes(digest[:8], "big"))


def make(
    kind: str,
    world: ScenarioWorld,
    actor: Body,
    properties: dict[str, str],
    active: frozenset[str],
    seed: int,
) -> EsminiController | None:
    """The controller of that kind on `actor`, active on `active` (of its operating domains); None when the
    kind is not in the registry or active on none of its domains."""
    domains = OPERATING_DOMAINS.get(kind, frozenset()) & active
    if not domains:
        return None
    if kind == "ALKS_R157SM_Controller":
        from simcore.scenario.controllers.alks_r157 import AlksR157Controller

        return AlksR157Controller(world, actor, properties)
    if kind == "LoomingController":
        from simcore.scenario.controllers.looming import LoomingController

        return LoomingController(world, actor, properties, domains)
    if kind == "FollowRouteController":
        from simcore.scenario.controllers.follow_route import FollowRouteController

        return FollowRouteController(world, actor, properties, domains)
    from simcore.scenario.controllers.sloppy import SloppyDriver

    return SloppyDriver(world, actor, properties, domains, rng_for(seed, actor.name))
