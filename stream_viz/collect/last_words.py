"""A crashed process's last words: the node of it that logged last as it died.

An exception out of a callback ends an rclpy process with a traceback on its stderr, which the
monitor does not read, and the nodes of a component container all leave with it alike. What the
monitor does see is ``/rosout``, every level: a node that logged in the moments before its
process died was running then — on one executor thread, the callback that logged is the one that
raised, more often than not ("Reloaded planogram … (0 bays)", then an ``IndexError``). So the
collector keeps each logger's newest line, and an exit names the node of its process that logged
last, within `LAST_WORDS_S` before it: of two that spoke then, the later ran closer to the end.
The same lines stamp each node's ``logged_at`` (`newest_lines`): a node that logged after every
message of its stalled executor's nodes was running when it stopped (`stream_viz.rca.siblings`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from stream_viz.collect.topics import logger_node

LAST_WORDS_S = 1.0  # how long before its process ended a line still counts as its last words
TEXT_MAX = 200  # characters of the line kept


def note_lines(lines: dict[str, tuple[float, str]], msgs: Iterable[Any]) -> None:
    """Keep in ``lines`` (logger name → (stamp, text)) the newest line of each logger among
    ``msgs`` (``rcl_interfaces/msg/Log``)."""
    for msg in msgs:
        try:
            t, name, text = msg.stamp.sec + msg.stamp.nanosec * 1e-9, str(msg.name), str(msg.msg)
        except (AttributeError, TypeError):  # a malformed message: `log_event` says so
            continue
        if t >= lines.get(name, (float("-inf"),))[0]:
            lines[name] = (t, text[:TEXT_MAX])


def last_words(lines: Mapping[str, tuple[float, str]], nodes: Iterable[str], start: float,
               end: float) -> tuple[str, float, str] | None:
    """Return ``(node, stamp, text)`` of the newest line any of ``nodes`` (fqns of one process)
    logged between ``start`` and ``end``, or None when none did.

    Parameters
    ----------
    lines : mapping
        Logger name → (stamp, text) of its newest line (`note_lines`); a child logger
        (``ns.node.child``) speaks for its node.
    nodes : iterable of str
        The process's node fqns.
    start, end : float
        The span the process may have died in, widened by `LAST_WORDS_S` before (s, unix).
    """
    fqns = frozenset(nodes)
    said = [(t, n, text) for logger, (t, text) in lines.items()
            if start <= t <= end and (n := logger_node(logger, fqns)) in fqns]
    if not said:
        return None
    t, n, text = max(said)
    return n, t, text


def newest_lines(lines: Mapping[str, tuple[float, str]], nodes: Iterable[str]) -> dict[str, float]:
    """Return node fqn → the stamp of its newest line (any level, its child loggers' too) among
    ``lines`` (`note_lines`), for the loggers that belong to one of ``nodes``."""
    fqns = frozenset(nodes)
    out: dict[str, float] = {}
    for logger, (t, _) in lines.items():
        n = logger_node(logger, fqns)
        if n in fqns and t > out.get(n, float("-inf")):
            out[n] = t
    return out
