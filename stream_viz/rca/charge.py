"""Who a symptom is charged to: the publishers of a topic, the servers of a service, the nodes an
alert names.

A symptom on a passive member says something is wrong with the nodes feeding it. With one
publisher that is the one; with several (``/tf``, ``/diagnostics``, a fan-in) the symptom is
charged to the publishers its alerts name (data ``publishers``: whose own stamps are late), else,
for a symptom the messages carry (stale, out of sync, late, lost: `CARRIED`), to those that send
them, else to those whose own traffic changed (``publisher_rates`` on the topic: a
publisher gone silent while the others go on), else to those with other evidence of their own
at that time (their other outputs, their own alerts, their process), else equally to all. An
alert that names a server, a service or a node (``data["server"]``, ``data["service"]``,
``data["names"]``: a client's ``/rosout`` line naming what it waits for, a service monitor's
alert) points at those nodes.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import networkx as nx

from stream_viz.model.graph import FLOW
from stream_viz.model.ids import KINDS
from stream_viz.model.queries import publishers, servers

LOW_SHARE = 0.25  # share of a publisher the other publishers' own evidence does not clear
NAME_KEYS = ("server", "service", "names")  # alert data that names the member to blame
# Symptoms a topic's messages carry (alert data ``symptom``): theirs who send them, not a standby's.
CARRIED = frozenset({"stale", "desync", "clock_skew", "latency_rise", "jitter_rise", "drops"})


def charged_nodes(G: nx.MultiDiGraph, member: str) -> list[str]:
    """Return the nodes a symptom of the passive ``member`` is charged to, sorted.

    A topic's publishers; a service's or action's servers (from the member's ``servers``, else
    the ``send`` edges that carry it).
    """
    if member.startswith(("service:", "action:")):
        return servers(G, member) or _servers_by_edge(G, member)
    return publishers(G, member)


def _servers_by_edge(G: nx.MultiDiGraph, service: str) -> list[str]:
    # The adjacency itself, not an edge view: this scans every edge, for each service asked.
    out = set()
    for nbrs in G._succ.values():
        for v, kd in nbrs.items():
            d = kd.get(FLOW)
            if d is not None and d.get("kind") == "send" and service in (d.get("services") or ()):
                out.add(v)
    return sorted(out)


def named_nodes(G: nx.MultiDiGraph, name: str) -> list[str]:
    """Return the nodes ``name`` points at, sorted: a node (id or ROS name) or the servers of a
    service or action (id or name); nothing for a name not in ``G``."""
    prefix = name.split(":", 1)[0]
    if ":" in name and prefix in KINDS:
        ids = [name]
    else:
        ros = name if name.startswith("/") else "/" + name
        ids = [f"node:{ros}", f"service:{ros}", f"action:{ros}"]
    out: set[str] = set()
    for m in ids:
        if m in G and G.nodes[m].get("kind") == "node":
            out.add(m)
        elif m.startswith(("service:", "action:")):
            out.update(charged_nodes(G, m) if m in G else _servers_by_edge(G, m))
    return sorted(out)


def names_in(data: Mapping[str, Any]) -> list[str]:
    """Return the names an alert's ``data`` gives of what to blame (not its ``client``)."""
    out: list[str] = []
    for key in NAME_KEYS:
        x = data.get(key)
        if isinstance(x, str):
            out.append(x)
        elif isinstance(x, list | tuple):
            out.extend(v for v in x if isinstance(v, str))
    return out


def pointed_nodes(G: nx.MultiDiGraph, member: str, names: Iterable[str]) -> list[str]:
    """Return the nodes the ``names`` of an alert on ``member`` point at (never ``member``), sorted."""
    out: set[str] = set()
    for name in names:
        out.update(named_nodes(G, name))
    out.discard(member)
    return sorted(out)


def publisher_shares(
    G: nx.MultiDiGraph, topic: str, pubs: list[str], other: Mapping[str, float], named: Iterable[str] = (),
    carried: bool = False,
) -> dict[str, float]:
    """Return the share of a symptom on ``topic`` that each of its publishers ``pubs`` carries.

    Parameters
    ----------
    G : MultiDiGraph
        The model; the topic's ``publisher_rates`` (node id → Hz), when present, tells whose
        traffic stopped; a publisher marked ``gone`` has stopped.
    topic : str
        The symptomatic topic.
    pubs : list of str
        Its publishers.
    other : mapping
        Each publisher's anomaly from evidence of its own at the time (0 or missing: none).
    named : iterable of str, optional
        The publishers the symptom's own alerts name (data ``publishers``: whose stamps are late).
    carried : bool, optional
        The symptom is carried by the messages (`CARRIED`): the publishers that send them carry
        it, not one that sends nothing (a hot standby), which would otherwise look stopped.

    Returns
    -------
    dict
        1 for the publishers the alerts name or the evidence points at; 0 for the others
        beside those named, for those sending nothing when the messages carry the symptom, and
        for those still publishing when others stopped; `LOW_SHARE` for
        those that the others' own evidence does not clear; 1 for all when nothing tells them
        apart (or there is a single publisher).
    """
    if len(pubs) < 2:
        return dict.fromkeys(pubs, 1.0)
    named = set(named) & set(pubs)
    if named and len(named) < len(pubs):
        return {p: 1.0 if p in named else 0.0 for p in pubs}
    rates = G.nodes[topic].get("publisher_rates") if topic in G else None
    rates = rates if isinstance(rates, Mapping) else {}
    if carried:
        sending = {p for p in pubs if not G.nodes[p].get("gone") and (_rate(rates.get(p)) or 0.0) > 0}
        if sending and len(sending) < len(pubs):
            return {p: 1.0 if p in sending else 0.0 for p in pubs}
    stopped = {p for p in pubs if G.nodes[p].get("gone") or _rate(rates.get(p)) == 0.0}
    if stopped and len(stopped) < len(pubs):
        return {p: 1.0 if p in stopped else 0.0 for p in pubs}
    suspect = {p for p in pubs if other.get(p, 0.0) > 0}
    if suspect and len(suspect) < len(pubs):
        return {p: 1.0 if p in suspect else LOW_SHARE for p in pubs}
    return dict.fromkeys(pubs, 1.0)


def _rate(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    return max(0.0, float(x))
