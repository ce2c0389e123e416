"""The one registry from OpenSCENARIO private action type to the runtime that implements it, and the
rules that let a controller override an action (`make_runtime`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

from simcore.errors import BadInput
from simcore.scenario import actions, core_actions
from simcore.scenario import model as m
from simcore.scenario.controller_actions import ControllerRuntime
from simcore.scenario.runtime import Instant, Runtime

if TYPE_CHECKING:
    from simcore.scenario.action_world import ActionWorld
    from simcore.scenario.motion import Body

#: private action type → its runtime (constructed with the world, the actor and the action)
PRIVATE_ACTIONS: Final[dict[type, Callable[[ActionWorld, Body, Any], Runtime]]] = {
    m.SpeedAction: core_actions.SpeedRuntime,
    m.LaneChangeAction: core_actions.LaneChangeRuntime,
    m.TeleportAction: core_actions.TeleportRuntime,
    m.LaneOffsetAction: actions.LaneOffsetRuntime,
    m.LongitudinalDistanceAction: actions.LongitudinalDistanceRuntime,
    m.LateralDistanceAction: actions.LateralDistanceRuntime,
    m.SpeedProfileAction: actions.SpeedProfileRuntime,
    m.FollowTrajectoryAction: actions.FollowTrajectoryRuntime,
    m.AssignRouteAction: actions.AssignRouteRuntime,
    m.AcquirePositionAction: actions.AcquirePositionRuntime,
    m.SynchronizeAction: actions.SynchronizeRuntime,
    m.TrailerAction: actions.TrailerRuntime,
    m.NoMotionAction: actions.NoMotionRuntime,
    m.ControllerAction: ControllerRuntime,
}

# the actions an active external controller does not override
_KEPT_UNDER_EXTERNAL_CONTROL: Final = (m.TeleportAction, m.NoMotionAction, m.AssignRouteAction)


class IgnoredRuntime(Instant):
    """A motion action on an entity an external controller drives: the controller overrides it."""

    def __init__(self, world: ActionWorld, actor: Body, action: m.PrivateAction) -> None:
        super().__init__(world, actor)
        self.domain = getattr(action, "domain", "other")

    def start(self) -> None:
        self.done = True


def overridden(world: ActionWorld, actor: Body, action: m.PrivateAction) -> bool:
    """A controller moves the actor in the action's domain, so the action does nothing (esmini ends it): an
    active external controller (all but placements and routes), an override-mode ACC or a NaturalDriver
    (longitudinal actions)."""
    if isinstance(action, m.ControllerAction):
        return False
    if actor.external:
        if isinstance(action, _KEPT_UNDER_EXTERNAL_CONTROL):
            return False
        # an external controller on one domain only (esmini's InteractiveController steering) leaves the
        # other to the scenario's actions and the entity's other controllers
        _, longitudinal, lateral = world.controllers[actor.name]
        domain = getattr(action, "domain", "")
        if domain == "lateral" and not lateral:
            return False
        if domain != "longitudinal" or longitudinal:
            return True
    if getattr(action, "domain", "") != "longitudinal":
        return False
    acc = world.acc_drivers.get(actor.name)
    if acc is not None and acc.override and not acc.virtual:
        return True
    return actor.name in world.natural_drivers


def make_runtime(world: ActionWorld, actor: Body, action: m.PrivateAction) -> Runtime:
    """The runtime of `action` on `actor` (one that does nothing when a controller overrides it)."""
    if overridden(world, actor, action):
        return IgnoredRuntime(world, actor, action)
    runtime = PRIVATE_ACTIONS.get(type(action))
    if runtime is None:
        raise BadInput(f"{type(action).__name__} is not supported", file=world.source)
    return runtime(world, actor, action)
