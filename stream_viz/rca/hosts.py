"""A computer as the root cause: its nodes' symptoms explained by the host they run on.

Candidates are nodes (`symptoms`); a host's own alert (`host_state`: saturated, out of sight)
reaches every node on it. When that alert began no later than anything else on the host went
wrong, and no process of the host has a symptom of its own (a CPU or memory rise, a crash seen
from its OS: then the load or the crash is that process's, and its node ranks as before), the
host explains its nodes and is ranked just above the first of them: a computer that went off
takes its nodes with it, a saturated one slows them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import networkx as nx

from stream_viz.model.ids import make_id
from stream_viz.model.queries import nodes_of_process
from stream_viz.rca.causal import publishers
from stream_viz.rca.symptoms import Symptoms

OWN_PROCESS_PLUGINS = ("process_resources",)  # a process's own load: the host is its victim
VICTIM = 0.5  # an explained node keeps this share of its score: still ranked, below its host


def host_of(G: nx.MultiDiGraph, member: str) -> str | None:
    """Return the host member (``host:<name>``) ``member`` runs on, or None (not known)."""
    host = G.nodes[member].get("host") if member in G else None
    return make_id("host", host) if host and make_id("host", host) in G else None


def explains(G: nx.MultiDiGraph, host: str, s: Symptoms, tolerance: float) -> bool:
    """True when ``host``'s own symptom explains its nodes' (module docstring).

    Parameters
    ----------
    G : MultiDiGraph
        The model (hosts, their processes and nodes in the process tree).
    host : str
        A host member.
    s : Symptoms
        The incident's symptoms (``began``: when an alert says its symptom began).
    tolerance : float
        Seconds a symptom of the host's may precede the host's own and still be its effect.
    """
    if host not in s.onset:
        return False
    began = s.began.get(host, s.onset[host])
    nodes = set(nodes_of_process(G, host))
    for m, onset in s.onset.items():
        on_host = m in nodes or (m in G and G.nodes[m].get("kind") == "process"
                                 and host_of(G, m) == host)
        if on_host and (s.plugins[m] & set(OWN_PROCESS_PLUGINS) or m in s.exited):
            return False
        fed = m.startswith("topic:") and (pubs := publishers(G, m)) and set(pubs) <= nodes
        if (on_host or fed) and onset < began - tolerance:
            return False
    return True


def lift_hosts(G: nx.MultiDiGraph, causes: Sequence[Any], s: Symptoms, tolerance: float) -> list[Any]:
    """Return ``causes`` (ranked `RootCause` objects) with each host that `explains` its nodes
    ranked just above the first of them, with that node's score and evidence (its own symptom
    and plugins, ``host``, ``explains_nodes``); its trajectory is the node's, then the host. The
    nodes it explains keep `VICTIM` of their score (``explained_by``: the host), so that none ties
    with it, and the list is sorted again by score (stable)."""
    if not any(m.startswith("host:") for m in s.onset):
        return list(causes)
    out: list[Any] = []
    seen: set[str] = set()
    by: dict[str, str] = {}  # explained node -> its host
    for rc in causes:
        host = host_of(G, rc.member)
        if host is not None and host not in seen:
            seen.add(host)
            if explains(G, host, s, tolerance):
                on = sorted(n for n in nodes_of_process(G, host) if n in {c.member for c in causes})
                by.update(dict.fromkeys(on, host))
                out.append(replace(rc, member=host, trajectory=[*rc.trajectory, host], evidence={
                    **rc.evidence, "symptoms": [host], "plugins": sorted(s.plugins[host]),
                    "host": host, "explains_nodes": on}))
        if rc.member in by:
            rc = replace(rc, score=rc.score * VICTIM, evidence={**rc.evidence, "explained_by": by[rc.member]})
        out.append(rc)
    return sorted(out, key=lambda rc: -rc.score)
