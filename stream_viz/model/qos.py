"""Reading the QoS profiles the collector keeps on endpoints (plain dicts in the model)."""

from __future__ import annotations

from typing import Any

# rclpy's enum numbers, as older models stored them
_NUMBERED = {
    "reliability": dict(enumerate(("system_default", "reliable", "best_effort", "unknown",
                                   "best_available"))),
    "durability": dict(enumerate(("system_default", "transient_local", "volatile", "unknown",
                                  "best_available"))),
    "liveliness": {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown",
                   5: "best_available"},
}


def qos_policy(qos: dict[str, Any], key: str) -> str:
    """A policy as rmw names it (``reliable``, ``best_effort``, ``volatile``, ``automatic``, …); '' if
    absent. Also reads rclpy's enum numbers and names (``ReliabilityPolicy.RELIABLE``)."""
    raw = qos.get(key)
    if isinstance(raw, int) and not isinstance(raw, bool):
        return _NUMBERED[key].get(raw, "")
    return str(raw or "").lower().rsplit(".", 1)[-1]
