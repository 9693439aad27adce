"""Member ids, exactly as docs/contracts.md fixes them: ``node:/ns/name``, ``process:<pid>`` (another
computer's: ``process:<host>/<pid>``), ``host:<name>``, ``root``."""

from __future__ import annotations

from stream_viz.errors import ModelError

ROOT = "root"
KINDS = ("node", "topic", "service", "action", "process", "host", "root")


def make_id(kind: str, name: str | int) -> str:
    """Return the member id of a member of ``kind`` called ``name``.

    Parameters
    ----------
    kind : str
        One of ``node``, ``topic``, ``service``, ``action``, ``process``, ``host``, ``root``.
    name : str or int
        A fully qualified ROS name (``/ns/name``), a pid, or a host name.
    """
    if kind == "root":
        return ROOT
    if kind not in KINDS:
        raise ModelError(f"unknown member kind {kind!r} (expected one of {', '.join(KINDS)})")
    if kind in ("node", "topic", "service", "action"):
        name = str(name)
        if not name.startswith("/"):
            name = "/" + name
    return f"{kind}:{name}"


def node_fqn(namespace: str, name: str) -> str:
    """Join a ROS namespace and node name into a fully qualified name (``/ns/name``)."""
    ns = namespace.rstrip("/")
    return f"{ns}/{name}" if ns else f"/{name}"


def kind_of(member: str) -> str:
    """Return the kind part of a member id (``node:/a`` -> ``node``)."""
    if member == ROOT:
        return "root"
    kind, sep, _ = member.partition(":")
    if not sep or kind not in KINDS:
        raise ModelError(f"malformed member id {member!r}")
    return kind


def name_of(member: str) -> str:
    """Return the name part of a member id (``node:/a`` -> ``/a``; ``root`` -> ``root``)."""
    if member == ROOT:
        return ROOT
    kind_of(member)
    return member.partition(":")[2]


def pid_of(member: str) -> int:
    """Return the pid of a ``process:<pid>`` (this host) or ``process:<host>/<pid>`` member id."""
    if kind_of(member) != "process":
        raise ModelError(f"{member!r} is not a process id")
    return int(name_of(member).rpartition("/")[2])
