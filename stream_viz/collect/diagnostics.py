"""/diagnostics and /diagnostics_agg statuses as ``diag`` events on the member they are about.

How robots name statuses (read in ros/diagnostics, ``ros2-jazzy``):

* ``diagnostic_updater`` publishes ``"<node name>: <task>"``: the node's base name, or with the
  parameter ``diagnostic_updater.use_fqn`` its fully qualified name (rclpy's form of it in the root
  namespace is ``"//name"``), and the updater's ``hardware_id`` (``setHardwareID``; often a
  device id such as a serial number, sometimes a node name, ``"none"`` when there is none).
* ``diagnostic_aggregator`` subscribes to /diagnostics and republishes on /diagnostics_agg:
  every status it matched as ``"<analyzer path>/<name with / replaced by spaces>"`` (minus a
  ``remove_prefix``), with its level, message and hardware id, and one status per analyzer named
  by its path (``/Robot/Sensors``) carrying the worst level below it; an item not updated within
  its timeout is republished as STALE.

A status is mapped to a node (`map_status`): by its name (the part before ``": "``, with or
without namespace, relative to its publisher's namespace; an aggregator path by its tail), then
by its hardware id (a node name, or hardware a node declared in a parameter), then to its
publisher (the gid of the message says which node sent it). ``mapped_by`` in the event says
which. An aggregator's copy of a status seen on /diagnostics is not counted twice; its analyzer
summaries are not counted at all; what only it knows (an item gone STALE, a status whose
original we never saw) is (`DiagnosticsReader`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from stream_viz.collect.naming import NodeNames, status_head
from stream_viz.records import Event

LEVELS = {0: "info", 1: "warn", 2: "error", 3: "warn"}  # OK → info so plugins can clear
NAMES = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
STALE = 3
AGG_TOPIC = "/diagnostics_agg"
MIN_HARDWARE = 3  # shorter declared parameter values are not taken for hardware ids


def level_of(status: Any) -> int:
    """Return a status level as an int (rclpy gives ``bytes`` of length 1)."""
    lvl = status.level
    return lvl[0] if isinstance(lvl, bytes | bytearray) else int(lvl)


def namespace_of(fqn: str | None) -> str:
    """Return the namespace of a node fqn (``/a/b`` → ``/a``; None or ``/b`` → ``/``)."""
    if not fqn:
        return "/"
    return fqn.rsplit("/", 1)[0] or "/"


def map_status(name: str, hardware_id: str, index: NodeNames, publisher: str | None,
               hardware: Mapping[str, str] | None = None) -> tuple[str | None, str]:
    """Return ``(node fqn or None, mapped_by)`` for a status.

    ``mapped_by`` is ``name`` (the status name's node part names a node, or is its fully
    qualified name with ``_`` for ``/``: `NodeNames.flattened`), ``hardware_id`` (its
    hardware id is a node's name, or hardware that node declared: ``hardware`` maps a hardware id
    to a node), ``publisher`` (the node that published it) or ``none``.
    """
    ns = namespace_of(publisher)
    head = status_head(name)
    node = index.resolve(head, ns) or index.flattened(head)
    if node is not None:
        return node, "name"
    hw = hardware_id.strip()
    if hw:
        node = index.resolve(hw, ns)
        if node is None and hardware:
            node = hardware.get(hw)
            node = node if node in index.fqns else None
        if node is not None:
            return node, "hardware_id"
    if publisher is not None:
        return publisher, "publisher"
    return None, "none"


def aggregator_groups(names: list[str]) -> set[str]:
    """Return the names in one /diagnostics_agg array that are analyzer summaries: the path of
    another status in it (``/Robot/Sensors`` of ``/Robot/Sensors/lidar: scan``)."""
    ordered = sorted(names)
    groups = set()
    for i, n in enumerate(ordered):
        # sorted: every name under n + "/" follows n directly or after other such names
        for m in ordered[i + 1:]:
            if m.startswith(n + "/"):
                groups.add(n)
                break
            if not m.startswith(n):
                break
    return groups


def aggregated_form(name: str) -> str:
    """Return how the aggregator writes a status name as the last element of its path."""
    return name.replace("/", " ")


class DeclaredHardware:
    """String parameter values nodes declared or set (from /parameter_events), for hardware ids.

    A hardware id equal to such a value of exactly one node maps to that node. Only parameters
    declared or changed while we observe are seen (/parameter_events is volatile).
    """

    def __init__(self) -> None:
        self.values: dict[str, set[str]] = {}  # node fqn -> string values

    def add(self, event: Any) -> None:
        """Take a ``rcl_interfaces/ParameterEvent``."""
        vals = self.values.setdefault(event.node, set())
        for p in (*event.new_parameters, *event.changed_parameters):
            v = p.value
            for s in (v.string_value, *v.string_array_value):
                if len(s) >= MIN_HARDWARE:
                    vals.add(s)

    def mapping(self) -> dict[str, str]:
        """Return hardware id → node for values exactly one node declared."""
        owners: dict[str, set[str]] = {}
        for node, vals in self.values.items():
            for v in vals:
                owners.setdefault(v, set()).add(node)
        return {v: next(iter(n)) for v, n in owners.items() if len(n) == 1}


class DiagnosticsReader:
    """Turns /diagnostics and /diagnostics_agg arrays into ``diag`` events, once per status.

    Parameters
    ----------
    copy_s : float
        An aggregator's status whose original came on /diagnostics within this long is a copy.
    stale_s : float
        An aggregator's STALE item counts only when its original has not come for this long.
    """

    def __init__(self, copy_s: float = 30.0, stale_s: float = 3.0) -> None:
        self.copy_s, self.stale_s = copy_s, stale_s
        self.seen: dict[str, tuple[float, str | None, str]] = {}  # name -> (t, node, mapped_by)
        self.by_form: dict[str, str] = {}  # aggregated form -> original name
        self.hardware = DeclaredHardware()

    def events(self, topic: str, msg: Any, t: float, publisher: str | None,
               index: NodeNames) -> list[Event]:
        """Return the events of one DiagnosticArray that came on ``topic`` from ``publisher``."""
        if topic == AGG_TOPIC:
            return self._aggregated(msg, t, index)
        hardware = self.hardware.mapping() if self.hardware.values else {}
        out = []
        for st in msg.status:
            node, by = map_status(st.name, st.hardware_id, index, publisher, hardware)
            self.seen[st.name] = (t, node, by)
            self.by_form[aggregated_form(st.name)] = st.name
            out.append(_event(st, t, node, by, topic, publisher))
        return out

    def _aggregated(self, msg: Any, t: float, index: NodeNames) -> list[Event]:
        groups = aggregator_groups([st.name for st in msg.status])
        hardware = self.hardware.mapping() if self.hardware.values else {}
        out = []
        for st in msg.status:
            if st.name in groups:
                continue  # an analyzer's summary of statuses counted one by one
            level = level_of(st)
            original = self._original(st.name)
            if original is not None:
                t_seen, node, by = self.seen[original]
                if t - t_seen <= (self.stale_s if level == STALE else self.copy_s):
                    continue  # a copy of what /diagnostics told us
            else:
                node, by = map_status(st.name.rsplit("/", 1)[-1], st.hardware_id, index, None, hardware)
            if level == STALE and node not in index.live:
                continue  # its node left the graph: that absence is the evidence, not this echo
            out.append(_event(st, t, node, by, AGG_TOPIC, None))
        return out

    def _original(self, agg_name: str) -> str | None:
        last = agg_name.rsplit("/", 1)[-1]
        if last in self.by_form:
            return self.by_form[last]
        # remove_prefix: the aggregator dropped the start of the name
        ends = [n for form, n in self.by_form.items() if form.endswith(last)]
        return ends[0] if len(ends) == 1 else None


def _event(st: Any, t: float, node: str | None, by: str, topic: str, publisher: str | None) -> Event:
    lvl = level_of(st)
    member = f"node:{node}" if node is not None else f"topic:{topic}"
    return Event(
        t, "diag", member, LEVELS.get(lvl, "warn"),
        f"{st.name}: {NAMES.get(lvl, lvl)} {st.message}".strip(),
        {"name": st.name, "hardware_id": st.hardware_id, "level": lvl,
         "values": {kv.key: kv.value for kv in st.values}, "mapped_by": by, "source": topic,
         "publisher": None if publisher is None else f"node:{publisher}"},
    )
