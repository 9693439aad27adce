"""Parameters changed at run time, from ``/parameter_events`` (observed only, nothing is called).

A roboticist tunes a running robot (``ros2 param set /camera rate_hz 4``) and its nodes change
their own settings (a zone manager setting a controller's speed limit): a change of a node's
configuration, after which its outputs may follow a new normal. Each ``ParameterEvent`` that
changes or deletes a parameter becomes one ``param`` event of that node; declarations
(``new_parameters`` alone, as every node sends when it starts) are not changes, nor is a value set
to what it already was (an executive applying a mode's whole configuration at every step, most
of it unchanged; ROS sends an event for every set).
"""

from __future__ import annotations

from typing import Any

from stream_viz.model.ids import make_id
from stream_viz.records import Event

# rcl_interfaces/ParameterType: the ParameterValue field each type keeps its value in
_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
           5: "byte_array_value", 6: "bool_array_value", 7: "integer_array_value",
           8: "double_array_value", 9: "string_array_value"}
MAX_VALUE_CHARS = 60  # a long array or string is cut in the event's text and data


def value_text(value: Any) -> str:
    """The value of a ``rcl_interfaces/ParameterValue`` as text, whole (``"?"`` when not set)."""
    field = _FIELDS.get(int(getattr(value, "type", 0)))
    if field is None:
        return "?"
    v = getattr(value, field)
    return repr(v) if isinstance(v, str) else str(list(v) if field.endswith("_array_value") else v)


def _short(text: str) -> str:
    """``text`` cut at `MAX_VALUE_CHARS` for an event's text and data."""
    return text if len(text) <= MAX_VALUE_CHARS else text[:MAX_VALUE_CHARS - 1] + "…"


def param_event(msg: Any, recv_s: float, known: dict[tuple[str, str], str] | None = None) -> Event | None:
    """The ``param`` event of a ``rcl_interfaces/ParameterEvent`` received at ``recv_s``, or None
    when it changes nothing (only declarations, values set to what ``known`` holds, or no node
    named). ``known`` ((node, parameter) → its value's full text) is kept up to date from every
    event, declarations included."""
    known = {} if known is None else known
    full = {p.name: value_text(p.value) for p in msg.changed_parameters}
    for p in msg.new_parameters:
        known[(msg.node, p.name)] = value_text(p.value)
    changed = {k: _short(v) for k, v in full.items() if known.get((msg.node, k)) != v}
    known.update({(msg.node, k): v for k, v in full.items()})
    deleted = [p.name for p in msg.deleted_parameters]
    for name in deleted:
        known.pop((msg.node, name), None)
    if not (changed or deleted) or not msg.node:
        return None
    parts = [f"{k} = {v}" for k, v in changed.items()] + [f"{k} deleted" for k in deleted]
    return Event(recv_s, "param", make_id("node", msg.node), "info",
                 f"parameter{'s' if len(parts) > 1 else ''} of {msg.node}: {', '.join(parts)}",
                 {"changed": changed, "deleted": deleted})
