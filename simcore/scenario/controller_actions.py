"""Assigning and activating controllers (ControllerAction): an external controller, or one of esmini's
driver models CARLOS runs (ACC/ALKS, NaturalDriver, OffroadFollower and the like), or FollowGhost."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from simcore.scenario import controllers, drivers
from simcore.scenario import model as m
from simcore.scenario.runtime import Instant

if TYPE_CHECKING:
    from simcore.scenario.action_world import ActionWorld
    from simcore.scenario.motion import Body


class ControllerRuntime(Instant):
    """Assign/activate a controller: an external one, active on any domain, moves the entity by its
    control input from now on (the scenario's motion actions on it are then ignored)."""

    domain = "none"

    def __init__(self, world: ActionWorld, actor: Body, action: m.ControllerAction) -> None:
        super().__init__(world, actor)
        self.action = action

    def start(self) -> None:
        control = self.world.controllers[self.actor.name]
        if self.action.assign is not None:
            control[0] = self.action.assign
        if self.action.longitudinal is not None:
            control[1] = self.action.longitudinal
        if self.action.lateral is not None:
            control[2] = self.action.lateral
        external = control[0] == "external" and (control[1] or control[2])
        self._driver_model(control, bool(external))
        ghosts = self.world.ghosts
        if ghosts is not None and ghosts.entity is self.actor:
            ghosts.activate(not external and (control[1] or control[2]))
        if external != self.actor.external:
            self.actor.external = bool(external)
            self.actor.mover = None
            self.world.log.append(
                f"t={self.world.time:.2f} {self.actor.name}: external controller "
                f"{'activated: moved by its control input' if external else 'deactivated'}"
            )
        self.done = True

    def _driver_model(self, control: list[Any], external: bool) -> None:
        """(Re)start or stop the driver model of an esmini controller CARLOS runs (ACC/ALKS): activated on
        the longitudinal domain, it starts from the entity's speed now (as esmini's Activate)."""
        e, name = self.world, self.actor.name
        if self.action.assign is not None:
            e.assigned_controller[name] = dict(self.action.controller)
        properties = e.assigned_controller.get(name, self.actor.entity.controller)
        kind = m.controller_type(properties)
        if kind in m.VEHICLE_CONTROLLERS and not external and (control[1] or control[2]):
            if self.action.assign is not None or name not in e.vehicle_drivers:
                e.vehicle_drivers[name] = drivers.OffroadFollower(e, self.actor, properties)
                e.log.append(f"t={e.time:.2f} {name}: {kind} controller activated")
        elif e.vehicle_drivers.pop(name, None) is not None:
            e.log.append(f"t={e.time:.2f} {name}: {kind or 'its'} controller deactivated")
        self._registered(kind, properties, control, external)
        if kind in m.NATURAL_DRIVER_CONTROLLERS and not external and control[1]:
            if self.action.longitudinal or self.action.assign is not None or name not in e.natural_drivers:
                e.natural_drivers[name] = drivers.NaturalDriver(e, self.actor, properties, e.natural_drivers)
                e.log.append(f"t={e.time:.2f} {name}: NaturalDriver activated at {self.actor.speed:.2f} m/s")
        elif e.natural_drivers.pop(name, None) is not None:
            e.log.append(f"t={e.time:.2f} {name}: NaturalDriver deactivated")
        if external or not control[1] or kind not in m.ACC_CONTROLLERS:
            if e.acc_drivers.pop(name, None) is not None:
                e.log.append(f"t={e.time:.2f} {name}: ACC controller deactivated")
            return
        if self.action.longitudinal or self.action.assign is not None or name not in e.acc_drivers:
            e.acc_drivers[name] = drivers.AccDriver(e, self.actor, properties)
            e.log.append(f"t={e.time:.2f} {name}: ACC controller activated at {self.actor.speed:.2f} m/s")

    def _registered(self, kind: str, properties: dict[str, str], control: list[Any], external: bool) -> None:
        """(Re)start or stop a controller of the registry (`simcore.scenario.controllers`): it runs on the
        domains it operates that are active; an activation or assignment restarts it (as esmini's Activate)."""
        e, name = self.world, self.actor.name
        active = frozenset(d for d, on in (("longitudinal", control[1]), ("lateral", control[2])) if on)
        made = None
        if kind in controllers.KINDS and not external:
            if name in e.esmini_controllers and not (
                self.action.assign is not None
                or self.action.longitudinal is not None
                or self.action.lateral is not None
            ):
                return
            made = controllers.make(kind, e, self.actor, properties, active, e.seed)
        if made is not None:
            e.esmini_controllers[name] = made
            e.log.append(f"t={e.time:.2f} {name}: {kind} activated ({', '.join(sorted(made.domains))})")
        elif e.esmini_controllers.pop(name, None) is not None:
            e.log.append(f"t={e.time:.2f} {name}: {kind or 'its'} controller deactivated")
