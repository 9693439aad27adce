"""Which nodes of a process began to warn as its symptom began: what tells the siblings apart.

Nodes in one process share its CPU and memory, so a process's rise cannot say whose work it is.
The node often says so itself: a WARN line ("falling back to CPU inference", "queue full,
dropping") or a diagnostics status that turns WARN. Alone such a warning is no symptom (robots
warn and recover: `rosout` alerts from ERROR, `diagnostics` on a WARN that holds). But a node
that began to warn, after ``quiet_s`` without a warning, as its process's symptom began is the
likely one of its siblings: the process's alert names it and the RCA charges it
(`stream_viz.rca.charge.NAME_KEYS`). A node that keeps warning began nothing then.
"""

from __future__ import annotations

from collections.abc import Iterable, MutableMapping

from stream_viz.records import SEVERITY_RANK, Event

STALE = 3  # a diagnostics status gone stale: its node stopped saying anything, it did not warn
KEEP = 4  # runs of warnings kept per node: older ones began long before any current symptom

Runs = MutableMapping[str, list[list]]  # node -> [[first, last, text], ...], oldest first


def is_warning(e: Event) -> bool:
    """True for a node's own WARN-or-worse log line or diagnostics status (not a STALE one)."""
    if not e.member.startswith("node:") or SEVERITY_RANK.get(e.level, -1) < SEVERITY_RANK["warn"]:
        return False
    return e.kind == "log" or (e.kind == "diag" and e.data.get("level") != STALE)


def note_warnings(runs: Runs, events: Iterable[Event], quiet_s: float) -> None:
    """Add the warnings among ``events`` to ``runs``: a node's warnings at most ``quiet_s`` apart
    are one run, whose text is its first warning's."""
    for e in events:
        if not is_warning(e):
            continue
        mine = runs.setdefault(e.member, [])
        run = mine[-1] if mine else None
        if run is not None and run[0] - quiet_s <= e.t <= run[1] + quiet_s:
            if e.t < run[0]:  # lines of one sample come in any order
                run[0], run[2] = e.t, e.text
            run[1] = max(run[1], e.t)
        else:
            mine.append([e.t, e.t, e.text])
            mine.sort(key=lambda r: r[0])
            del mine[:-KEEP]


def began_warning(runs: Runs, nodes: Iterable[str], since: float) -> list[tuple[str, str]]:
    """Return ``(node, its first warning)`` for each of ``nodes`` whose run of warnings began at
    ``since`` or later, sorted by node.

    Parameters
    ----------
    runs : mapping
        Node → its runs of warnings (`note_warnings`).
    nodes : iterable of str
        The nodes asked (a process's).
    since : float
        When the symptom began, less the lead a warning may have on it.
    """
    out = []
    for n in sorted(set(nodes)):
        began = [r for r in runs.get(n, ()) if r[0] >= since]
        if began:
            out.append((n, began[0][2]))
    return out
