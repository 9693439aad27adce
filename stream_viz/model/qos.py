"""Reading the QoS profiles the collector keeps on endpoints (plain dicts in the model), and
whether a publisher's and a subscription's can match (`compatibility`: rmw's rules, which the
`qos_compat` plugin alerts on and `rosout` asks before it names an input's publisher)."""

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


UNSPECIFIED = 0  # rmw's default deadline / lease duration (RMW_DURATION_UNSPECIFIED)
_UNKNOWN = ("system_default", "unknown")


def compatibility(pub: dict[str, Any], sub: dict[str, Any]) -> tuple[str, list[str]]:
    """Return ``("ok" | "warning" | "error", reasons)`` for a publisher and a subscription QoS.

    The rules and reason texts of rmw's ``qos_profile_check_compatible`` (module docstring);
    durations are ns (``deadline_ns``, ``liveliness_lease_ns``; 0 = unspecified). A key missing
    from a dict (an older model) is not checked.
    """
    errors = []
    p, s = _policies(pub), _policies(sub)
    if p["reliability"] == "best_effort" and s["reliability"] == "reliable":
        errors.append("Best effort publisher and reliable subscription")
    if p["durability"] == "volatile" and s["durability"] == "transient_local":
        errors.append("Volatile publisher and transient local subscription")
    _durations(pub, sub, "deadline_ns", errors, "Subscription has a deadline, but publisher does not",
               "Subscription deadline is less than publisher deadline")
    if p["liveliness"] == "automatic" and s["liveliness"] == "manual_by_topic":
        errors.append("Publisher's liveliness is automatic and subscription's is manual by topic")
    _durations(pub, sub, "liveliness_lease_ns", errors,
               "Subscription has a liveliness lease duration, but publisher does not",
               "Subscription liveliness lease duration is less than publisher")
    if errors:
        return "error", errors
    warnings = _warnings(p, s)
    return ("warning", warnings) if warnings else ("ok", [])


def _durations(pub: dict[str, Any], sub: dict[str, Any], key: str, errors: list[str], none: str,
               less: str) -> None:
    """rmw's two rules for a requested duration (deadline, lease): the publisher offers none, or
    a longer one than the subscription requests."""
    pd, sd = pub.get(key), sub.get(key)
    if not isinstance(pd, int) or not isinstance(sd, int):
        return
    if pd == UNSPECIFIED and sd != UNSPECIFIED:
        errors.append(none)
    if pd != UNSPECIFIED and sd != UNSPECIFIED and sd < pd:
        errors.append(less)


def _warnings(p: dict[str, str], s: dict[str, str]) -> list[str]:
    """rmw's warnings (policies it cannot judge), in its order and words."""
    out = []
    # ("durabilty" is rmw's own spelling in that message)
    for key, both, sub_needs, sub_text, pub_gives, pub_text in (
        ("reliability", "Publisher reliability is {p} and subscription reliability is {s}", "reliable",
         "Reliable subscription, but publisher is {p}", "best_effort",
         "Best effort publisher, but subscription is {s}"),
        ("durability", "Publisher durabilty is {p} and subscription durability is {s}", "transient_local",
         "Transient local subscription, but publisher is {p}", "volatile",
         "Volatile publisher, but subscription is {s}"),
        ("liveliness", "Publisher liveliness is {p} and subscription liveliness is {s}", "manual_by_topic",
         "Subscription's liveliness is manual by topic, but publisher's is {p}", "automatic",
         "Publisher's liveliness is automatic, but subscription's is {s}"),
    ):
        pv, sv = p[key], s[key]
        if not pv or not sv:
            continue
        pu, su = pv in _UNKNOWN, sv in _UNKNOWN
        if pu and su:
            out.append(both.format(p=pv, s=sv))
        elif pu and sv == sub_needs:
            out.append(sub_text.format(p=pv))
        elif pv == pub_gives and su:
            out.append(pub_text.format(s=sv))
    return out


def _policies(qos: dict[str, Any]) -> dict[str, str]:
    return {k: qos_policy(qos, k) for k in ("reliability", "durability", "liveliness")}
