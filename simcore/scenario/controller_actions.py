"""Assigning and activating controllers (ControllerAction): an external controller, or one of esmini's
driver models CARLOS runs (ACC/ALKS, NaturalDriver, OffroadFollower and the like), or FollowGhost.

An entity may have several controllers (several ObjectControllers, OpenSCENARIO 1.3, and every controller
an AssignControllerAction gives it), each active on some domains. As esmini:

- an AssignControllerAction adds its controller to the entity's (the most recently assigned last; assigned
  again, it moves to the end); its activateLongitudinal / activateLateral activate it on those domains
  without touching the others' domains;
- an ActivateControllerAction activates the controller its objectControllerRef names, else the most recently
  assigned one: each domain it switches on is first taken from any other controller active on it (a later
  activation overrides a conflicting one), each it switches off is released, the others stay as they are;
- so one controller may drive the longitudinal domain and another the lateral one (an ACC with an
  InteractiveController steering; an ALKS_R157SM model with another one's lane keeping)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from simcore.scenario import controllers, drivers
from simcore.scenario import model as m
from simcore.scenario.runtime import Instant

if TYPE_CHECKING:
    from simcore.scenario.action_world import ActionWorld
    from simcore.scenario.motion import Body

LONG, LAT = "longitudinal", "lateral"

#: per entity: controller name → [its properties, the domains it is active on], most recently assigned last
Slots = dict[str, tuple[dict[str, str], set[str]]]


def slots_of(world: ActionWorld, actor: Body) -> Slots:
    """The controllers assigned to `actor` (its ObjectControllers until an action assigns another)."""
    found: Slots | None = world.controller_slots.get(actor.name)
    if found is None:
        entity = actor.entity
        given = entity.controllers or ((entity.controller,) if entity.controller else ())
        found = {p.get("name", ""): (dict(p), set()) for p in given}
        world.controller_slots[actor.name] = found
    return found


def _is_external(properties: dict[str, str]) -> bool:
    return (
        properties.get("carlos.driver") == "external"
        or m.controller_type(properties) in m.EXTERNAL_CONTROLLERS
    )


class ControllerRuntime(Instant):
    """Assign/activate a controller: an external one, active on any domain, moves the entity by its
    control input from now on (the scenario's motion actions on it are then ignored)."""

    domain = "none"

    def __init__(self, world: ActionWorld, actor: Body, action: m.ControllerAction) -> None:
        super().__init__(world, actor)
        self.action = action

    def start(self) -> None:
        self.done = True
        e, action, name = self.world, self.action, self.actor.name
        slots = slots_of(e, self.actor)
        requested = {LONG: action.longitudinal, LAT: action.lateral}
        if action.assign is not None:
            properties = dict(action.controller)
            target = properties.get("name", "")
            slots.pop(target, None)
            slots[target] = (properties, set())
            e.assigned_controller[name] = properties
        else:
            target = action.ref if action.ref is not None else (next(reversed(slots)) if slots else "")
            if target not in slots:  # objectControllerRef names the ObjectController
                target = next(
                    (k for k, (p, _) in slots.items() if p.get(m.OBJECT_CONTROLLER) == target), target
                )
            if target not in slots:
                which = f"controller {target!r}" if action.ref is not None else "a controller"
                e.log.append(
                    f"t={e.time:.2f} {name}: ActivateControllerAction: {which} is not assigned to it"
                )
                return
            # a domain switched on is first taken from any other controller active on it
            for domain, on in requested.items():
                if on:
                    for other, (_, domains) in slots.items():
                        if other != target and domain in domains:
                            domains.discard(domain)
                            e.log.append(f"t={e.time:.2f} {name}: controller {other!r} released {domain}")
        domains = slots[target][1]
        for domain, on in requested.items():
            if on is True:
                domains.add(domain)
            elif on is False:
                domains.discard(domain)
        self._apply(slots, target)

    # --- the models that run, from the controllers' domains -------------------------------------------

    def _apply(self, slots: Slots, target: str) -> None:
        """(Re)start or stop the driver models and the external driving of the entity from what each of its
        controllers is active on now. The controller `target` of this action restarts (as esmini's Activate):
        a longitudinal driver model when assigned or switched on longitudinally, a controller of the registry
        when assigned or (de)activated on any domain, a vehicle model when assigned."""
        action = self.action
        assigned = action.assign is not None
        touched = assigned or action.longitudinal is not None or action.lateral is not None
        e, name, actor = self.world, self.actor.name, self.actor
        external_domains: set[str] = set()
        for properties, domains in slots.values():
            if _is_external(properties):
                external_domains |= domains
        external = bool(external_domains)
        control = e.controllers[name]
        control[0] = "external" if external else "scenario"
        control[1], control[2] = LONG in external_domains, LAT in external_domains
        ghosts = e.ghosts
        if ghosts is not None and ghosts.entity is actor:
            ghosts.activate(
                not external
                and any(m.controller_type(p) == "FollowGhostController" and d for p, d in slots.values())
            )
        if external != actor.external:
            actor.external = external
            actor.mover = None
            e.log.append(
                f"t={e.time:.2f} {name}: external controller "
                f"{'activated: moved by its control input' if external else 'deactivated'}"
            )
        longitudinal_free = LONG not in external_domains

        def active(kinds: frozenset[str], domain: str | None) -> tuple[str, dict[str, str]] | None:
            for key, (properties, domains) in slots.items():
                if m.controller_type(properties) in kinds and (
                    domains if domain is None else domain in domains
                ):
                    return key, properties
            return None

        def fresh(key: str, running: bool, restarts: bool) -> bool:
            return (key == target and restarts) or not running

        follower = active(m.VEHICLE_CONTROLLERS, None) if not external else None
        if follower is not None:
            if fresh(follower[0], name in e.vehicle_drivers, assigned):
                e.vehicle_drivers[name] = drivers.OffroadFollower(e, actor, follower[1])
                e.log.append(f"t={e.time:.2f} {name}: {m.controller_type(follower[1])} controller activated")
        elif e.vehicle_drivers.pop(name, None) is not None:
            e.log.append(f"t={e.time:.2f} {name}: OffroadFollower controller deactivated")
        self._registered(slots, target if touched else None, external_domains)
        natural = active(m.NATURAL_DRIVER_CONTROLLERS, LONG) if not external else None
        if natural is not None:
            if fresh(natural[0], name in e.natural_drivers, assigned or bool(action.longitudinal)):
                e.natural_drivers[name] = drivers.NaturalDriver(e, actor, natural[1], e.natural_drivers)
                e.log.append(f"t={e.time:.2f} {name}: NaturalDriver activated at {actor.speed:.2f} m/s")
        elif e.natural_drivers.pop(name, None) is not None:
            e.log.append(f"t={e.time:.2f} {name}: NaturalDriver deactivated")
        acc = active(m.ACC_CONTROLLERS, LONG) if longitudinal_free else None
        if acc is not None:
            if fresh(acc[0], name in e.acc_drivers, assigned or bool(action.longitudinal)):
                e.acc_drivers[name] = drivers.AccDriver(e, actor, acc[1])
                e.log.append(f"t={e.time:.2f} {name}: ACC controller activated at {actor.speed:.2f} m/s")
        elif e.acc_drivers.pop(name, None) is not None:
            e.log.append(f"t={e.time:.2f} {name}: ACC controller deactivated")

    def _registered(self, slots: Slots, restarted: str | None, external: set[str]) -> None:
        """(Re)start or stop the controller of the registry (`simcore.scenario.controllers`) active on the
        entity: it runs on the domains it operates that are active; an activation or assignment restarts it
        (as esmini's Activate)."""
        e, name = self.world, self.actor.name
        chosen: tuple[str, str, dict[str, str], frozenset[str]] | None = None
        for key, (properties, domains) in slots.items():
            kind = m.controller_type(properties)
            free = domains - external  # the domains an external controller does not hold
            if kind in controllers.KINDS and free & controllers.OPERATING_DOMAINS[kind]:
                chosen = key, kind, properties, frozenset(free)
        if chosen is None:
            if e.esmini_controllers.pop(name, None) is not None:
                e.log.append(f"t={e.time:.2f} {name}: its controller deactivated")
            return
        key, kind, properties, active = chosen
        running = e.esmini_controllers.get(name)
        if (
            running is not None
            and key != restarted
            and running.domains == active & controllers.OPERATING_DOMAINS[kind]
        ):
            return
        made = controllers.make(kind, e, self.actor, properties, active, e.seed)
        if made is not None:
            e.esmini_controllers[name] = made
            e.log.append(f"t={e.time:.2f} {name}: {kind} activated ({', '.join(sorted(made.domains))})")
