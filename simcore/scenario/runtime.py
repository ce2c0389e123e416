"""The runtime of one OpenSCENARIO private action on one actor (esmini's OSCPrivateAction): started once,
stepped every step until done. Each action type's runtime owns its behaviour; `action_registry` maps the
types to them."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simcore.scenario.action_world import ActionWorld
    from simcore.scenario.motion import Body


class Runtime:
    domain = "other"  # the domain it controls: a new action of the same domain on the actor overrides it

    def __init__(self, world: ActionWorld, actor: Body) -> None:
        self.world = world
        self.actor = actor
        self.done = False

    def start(self) -> None: ...

    def step(self, dt: float) -> None: ...

    def stop(self) -> None:
        """Another action took over (or the storyboard element stopped) before this one was done."""

    def start_in_init(self) -> bool:
        """As an action of Storyboard/Init: take effect now and return True, or return False to be started
        with the Init actions that run from the first step (the default: actions with a duration)."""
        return False


class Instant(Runtime):
    """An action that takes effect at once when started (a placement, a route, a controller)."""

    def start_in_init(self) -> bool:
        self.start()
        return True
