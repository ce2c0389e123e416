"""OpenSCENARIO global actions: one function per type and the registry that maps each type to it. They
take effect at once (parameters and variables, entities added or deleted, traffic signals)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

from simcore.errors import BadInput
from simcore.scenario import model as m

if TYPE_CHECKING:
    from simcore.scenario.world import ScenarioWorld


def run(world: ScenarioWorld, action: m.GlobalAction) -> None:
    """Carry out a global action."""
    GLOBAL_ACTIONS[type(action)](action, world)


def set_or_modify(action: m.ParameterSetAction | m.ParameterModifyAction, world: ScenarioWorld) -> None:
    """ParameterSetAction / ParameterModifyAction (and the Variable ones): the new value keeps the type of
    the declared one."""
    store = world.variables if action.variable else world.parameter_values
    if action.name not in store:
        kind = "variable" if action.variable else "parameter"
        raise BadInput(f"{kind} {action.name!r} is not declared", file=world.source)
    old = store[action.name]
    if isinstance(action, m.ParameterSetAction):
        new: Any = action.value
        if isinstance(old, bool):
            new = action.value.lower() in ("true", "1")
        elif isinstance(old, int):
            new = int(float(action.value))
        elif isinstance(old, float):
            new = float(action.value)
    else:
        base = float(old)
        new = base + action.value if action.rule == "add" else base * action.value
        if isinstance(old, int) and not isinstance(old, bool) and new == int(new):
            new = int(new)
    store[action.name] = new
    world.log.append(f"t={world.time:.2f} {action.name} := {new}")


def add_entity(action: m.AddEntityAction, world: ScenarioWorld) -> None:
    """AddEntityAction: the entity comes into the world at the position; one already in it stays where it
    is (esmini skips the action)."""
    body = world.body(action.entity)
    if not body.gone:
        world.log.append(f"t={world.time:.2f} AddEntityAction: {body.name} is already in the world: skipped")
        return
    body.gone = False
    world.place(body, action.position)


def delete_entity(action: m.DeleteEntityAction, world: ScenarioWorld) -> None:
    world.body(action.entity).gone = True
    world.moved()


def signal_state(action: m.TrafficSignalStateAction, world: ScenarioWorld) -> None:
    world.signals[action.name] = action.state
    world.log.append(f"t={world.time:.2f} signal {action.name} := {action.state}")


def signal_controller(action: m.TrafficSignalControllerAction, world: ScenarioWorld) -> None:
    world.signal_control.set_phase(action.controller, action.phase, world.time, world.source)


def no_motion(action: m.NoMotionGlobalAction, world: ScenarioWorld) -> None:
    """A global action with no effect on the run (accepted and ignored)."""


#: global action type → what it does
GLOBAL_ACTIONS: Final[dict[type, Callable[[Any, ScenarioWorld], None]]] = {
    m.ParameterSetAction: set_or_modify,
    m.ParameterModifyAction: set_or_modify,
    m.AddEntityAction: add_entity,
    m.DeleteEntityAction: delete_entity,
    m.TrafficSignalStateAction: signal_state,
    m.TrafficSignalControllerAction: signal_controller,
    m.NoMotionGlobalAction: no_motion,
}
