"""Which node or service of the graph a name in free text refers to. Pure.

Robots name their members loosely: a ``diagnostic_updater`` status is ``"<node name>: <task>"``
with or without the namespace (``use_fqn``; rclpy's fqn form even gives ``"//talker"``), a
diagnostic aggregator republishes it as ``"/Robot/Sensors/<name with / as spaces>"``, a hardware
id may be a node's name, a log line says ``"service /plan not available"`` or ``"planner timed
out"``. `NodeNames` resolves such a name to one node fully qualified name, or to none when it is
ambiguous.
"""

from __future__ import annotations

import re
from collections.abc import Container, Iterable, Mapping

_SEP = re.compile(r"[/\s]+")
# A ROS-name-like token in free text: an optional ~ or leading /, then name tokens joined by /.
_NAME = re.compile(r"(?<![\w/~])~?/?[A-Za-z_]\w*(?:/[A-Za-z_]\w*)*")
_WORD = re.compile(r"[A-Za-z0-9]+")  # the words of a line, as namespaces are spelt in it ("r1:")
MIN_BASE = 3  # a bare word shorter than this is not taken for a node's base name
LEFT_NAMES_S = 60.0  # a node that left is still named in /diagnostics and logs this long (a crash)


def tokens(name: str) -> list[str]:
    """Return the name tokens of ``name``, split on ``/`` and whitespace (empty ones dropped)."""
    return [t for t in _SEP.split(name) if t]


def join(namespace: str, toks: list[str]) -> str:
    """Return the fully qualified name of ``toks`` under ``namespace`` (``/`` for the root)."""
    ns = namespace.rstrip("/")
    return ns + "/" + "/".join(toks)


class NodeNames:
    """The node names of a graph, indexed for `resolve`.

    Parameters
    ----------
    nodes : iterable of str
        Fully qualified node names.
    left : iterable of str
        Nodes that left the graph lately: still resolved (a status or a log line about a crashed
        node), not in ``live``.
    """

    def __init__(self, nodes: Iterable[str], left: Iterable[str] = ()) -> None:
        self.live = frozenset(nodes)
        self.fqns = self.live | frozenset(left)
        self.by_base: dict[str, list[str]] = {}
        self.by_flat: dict[str, list[str]] = {}
        for fqn in sorted(self.fqns):
            self.by_base.setdefault(fqn.rsplit("/", 1)[-1], []).append(fqn)
            self.by_flat.setdefault(fqn.strip("/").replace("/", "_"), []).append(fqn)

    def flattened(self, name: str) -> str | None:
        """Return the one node whose fully qualified name, its ``/`` as ``_``, is ``name``
        (``r1_localizer`` → ``/r1/localizer``: a namespaced node's name as updaters and logs
        often spell it), or None."""
        found = self.by_flat.get(name.strip().strip("/"), [])
        return found[0] if len(found) == 1 else None

    def resolve(self, name: str, namespace: str = "/", bare: bool = True, tails: bool = True,
                words: frozenset[str] = frozenset()) -> str | None:
        """Return the node ``name`` refers to, or None.

        In order: the name as a fully qualified name and relative to ``namespace`` (the namespace
        first for a relative name, as ROS resolves it); with ``tails``,
        the longest tail of its tokens as a fully qualified name (an aggregator's
        ``/Robot/Sensors/lidar`` → ``/lidar``) or under ``namespace``; with ``bare``, the last
        token as the base name of exactly one node (of several, the one under ``namespace``, else
        the one whose namespace has a token among ``words``, lower case: a fleet manager's
        "r1: goal not acknowledged by the planner" is about ``/r1/planner``).
        """
        toks = tokens(name)
        if not toks:
            return None
        # a relative name resolves in the namespace first, as ROS resolves it
        if namespace == "/":
            spaces: tuple[str, ...] = ("/",)
        else:
            spaces = ("/", namespace) if name.startswith("/") else (namespace, "/")
        for k in range(len(toks) if tails else 1):
            tail = toks[k:]
            for ns in spaces:
                fqn = join(ns, tail)
                if fqn in self.fqns:
                    return fqn
        if not bare or len(toks[-1]) < MIN_BASE:
            return None
        found = self.by_base.get(toks[-1], [])
        if len(found) == 1:
            return found[0]
        inside = [f for f in found if f.rsplit("/", 1)[0] == namespace.rstrip("/")]
        if len(inside) == 1 or not words:
            return inside[0] if len(inside) == 1 else None
        told = [f for f in found if words & {t.lower() for t in tokens(f)[:-1]}]
        return told[0] if len(told) == 1 else None


def status_head(name: str) -> str:
    """Return the part of a diagnostic status name before ``": "`` (the updater's node name),
    or the whole name when it has none."""
    head, sep, _ = name.partition(": ")
    return head if sep else name


def named_in_text(text: str, index: NodeNames, services: Iterable[str], namespace: str = "/",
                  node: str | None = None) -> tuple[list[str], list[str]]:
    """Return ``(nodes, services)`` a line of text names (fully qualified, sorted).

    ``namespace`` and ``node`` are the writer's (relative and private ``~/`` names resolve
    against them; the writer itself is not listed). Services are matched by their full name,
    relative or private; nodes as `NodeNames.resolve`, bare base names included.
    """
    srv = set(services)
    found_nodes: set[str] = set()
    found_services: set[str] = set()
    words = frozenset(w.lower() for w in _WORD.findall(text))
    for m in _NAME.finditer(text):
        word = m.group(0)
        if word.startswith("~"):
            cands = [join(node or namespace, tokens(word[1:]))]
        elif word.startswith("/"):
            cands = [word]
        else:
            cands = [join(namespace, tokens(word)), join("/", tokens(word))]
        hit = next((c for c in cands if c in srv), None)
        if hit is not None:
            found_services.add(hit)
            continue
        if word.startswith(("~", "/")):  # private or absolute: that name exactly
            n = cands[0] if cands[0] in index.fqns else None
        else:
            n = index.resolve(word, namespace, tails=False, words=words)
        if n is not None and n != node:
            found_nodes.add(n)
    return sorted(found_nodes), sorted(found_services)


def recently_left(left: Mapping[str, float], before: Iterable[str], now: Container[str], t: float,
                  keep_s: float = LEFT_NAMES_S) -> dict[str, float]:
    """Return the nodes that left the graph within ``keep_s`` before ``t``, with when they left.

    ``left`` is the previous answer, ``before`` the nodes of the previous sample, ``now`` those
    of this one (a node that is back is not left).
    """
    out = {n: t0 for n, t0 in left.items() if n not in now and t - t0 < keep_s}
    out.update({n: t for n in before if n not in now and n not in out})
    return out
