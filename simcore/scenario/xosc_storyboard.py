"""The storyboard for the OpenSCENARIO parser: Init's actions, and Story → Act → ManeuverGroup (its
maneuvers inline or from a catalog) → Maneuver → Event → Action, with each level's parameter declarations
and triggers; a UserDefinedAction is warned about and ignored.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from simcore.scenario import model as m
from simcore.scenario.xosc_actions import _global, _private
from simcore.scenario.xosc_catalogs import _catalog_entry
from simcore.scenario.xosc_conditions import _start_trigger, _trigger
from simcore.scenario.xosc_reader import _Reader


def _init(reader: _Reader, init: ET.Element) -> list[m.InitAction]:
    out: list[m.InitAction] = []
    actions = init.find("Actions")
    if actions is None:
        return out
    for private in actions.findall("Private"):
        entity = reader.attr(private, "entityRef")
        for action in private.findall("PrivateAction"):
            out.append(
                m.InitAction(entity=entity, action=reader.within(private, entity, _private, reader, action))
            )
    for other in actions.findall("GlobalAction"):
        g = reader.within(other, None, _global, reader, other)
        out.append(m.InitAction(entity="", action=g))
    for other in actions.findall("UserDefinedAction"):
        reader.warn("UserDefinedAction is ignored", other)
    return out


def _story(reader: _Reader, story: ET.Element) -> m.Story:
    reader.push_declarations(story)
    try:
        acts = tuple(reader.within(a, a.get("name"), _act, reader, a) for a in story.findall("Act"))
    finally:
        reader.pop()
    return m.Story(name=reader.attr(story, "name"), acts=acts)


def _act(reader: _Reader, act: ET.Element) -> m.Act:
    start = act.find("StartTrigger")
    stop = act.find("StopTrigger")
    return m.Act(
        name=reader.attr(act, "name"),
        groups=tuple(
            reader.within(g, g.get("name"), _group, reader, g) for g in act.findall("ManeuverGroup")
        ),
        start_trigger=_start_trigger(reader, start),
        stop_trigger=_trigger(reader, stop) if stop is not None else None,
    )


def _group(reader: _Reader, group: ET.Element) -> m.ManeuverGroup:
    actors_el = group.find("Actors")
    actors: tuple[str, ...] = ()
    select = False
    if actors_el is not None:
        select = reader.boolean(actors_el, "selectTriggeringEntities", False)
        actors = tuple(reader.attr(r, "entityRef") for r in actors_el.findall("EntityRef"))
    maneuvers = [reader.within(mv, mv.get("name"), _maneuver, reader, mv) for mv in group.findall("Maneuver")]
    for ref in group.findall("CatalogReference"):
        entry, assignments = _catalog_entry(reader, ref, reader.catalogs, "Maneuver")
        if entry.tag != "Maneuver":
            raise reader.fail(f"catalog entry is a {entry.tag}, not a Maneuver", ref)
        reader.push_declarations(entry, assignments)
        try:
            maneuvers.append(reader.within(entry, entry.get("name"), _maneuver, reader, entry, False))
        finally:
            reader.pop()
    return m.ManeuverGroup(
        name=reader.attr(group, "name"),
        maximum_execution_count=reader.integer(group, "maximumExecutionCount", 1),
        actors=actors,
        select_triggering_entities=select,
        maneuvers=tuple(maneuvers),
    )


def _maneuver(reader: _Reader, maneuver: ET.Element, declare: bool = True) -> m.Maneuver:
    if declare:
        reader.push_declarations(maneuver)
    try:
        events = tuple(reader.within(e, e.get("name"), _event, reader, e) for e in maneuver.findall("Event"))
    finally:
        if declare:
            reader.pop()
    return m.Maneuver(name=reader.attr(maneuver, "name"), events=events)


def _event(reader: _Reader, event: ET.Element) -> m.Event:
    priority = reader.attr(event, "priority", "override")
    if priority not in ("override", "overwrite", "skip", "parallel"):
        raise reader.fail(f"priority={priority!r}: expected override, overwrite, skip or parallel", event)
    start = event.find("StartTrigger")
    actions = []
    for action in event.findall("Action"):
        name = reader.attr(action, "name")
        private = action.find("PrivateAction")
        if private is not None:
            actions.append(
                m.Action(name=name, private=reader.within(action, name, _private, reader, private))
            )
            continue
        if not any(isinstance(c.tag, str) for c in action):
            # an empty <Action/>: nothing to do, it ends at once (as esmini runs it)
            reader.within(action, name, reader.warn, "an empty Action does nothing", action)
            actions.append(m.Action(name=name, private=None))
            continue
        inner = reader.only_child(action)
        if inner.tag == "GlobalAction":
            g = reader.within(action, name, _global, reader, inner)
            actions.append(m.Action(name=name, private=None, global_action=g))
        else:
            reader.within(action, name, reader.warn, f"{inner.tag} is ignored", inner)
            actions.append(m.Action(name=name, private=None))
    return m.Event(
        name=reader.attr(event, "name"),
        priority=priority,  # type: ignore[arg-type]
        maximum_execution_count=reader.integer(event, "maximumExecutionCount", 1),
        actions=tuple(actions),
        start_trigger=_start_trigger(reader, start),
    )
