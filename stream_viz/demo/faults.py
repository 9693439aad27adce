"""The fault kinds the demo can inject and their validated specification."""

from __future__ import annotations

import threading
from dataclasses import dataclass

from stream_viz.errors import DemoError

STOP = threading.Event()  # the process is ending: releases hung callbacks, ends fault threads

FAULTS: dict[str, str] = {
    "crash": "the target's process kills itself (SIGKILL): every node of that process is gone",
    "hang": "the target node's callbacks block forever: it stops publishing and serving",
    "degrade": "the target publishes only every 4th message (~1/4 of its rate)",
    "cpu": "a thread in the target's process burns a full core",
    "leak": "the target's process allocates ~20 MB/s, capped at 1.5 GB",
    "delay": "every callback of the target sleeps 50-400 ms: its rate drops, its jitter rises",
    "errlog": "the target logs an ERROR line every 0.5 s (to /rosout)",
    "diag": "/diagnostics reports ERROR for the target (status name and hardware_id = its fqn)",
    # Kinds that need structures the first demo does not have (the warehouse AMR, ``demo/amr``).
    "slow_service": "the target's service callbacks take 5 s: its clients time out and stall",
    "qos": "the target re-creates its best-effort subscriptions as reliable: they receive nothing",
    "restart": "the target's process exits (code 1) ~3 s after each start; its launcher respawns it",
    "flap": "the target's publishers drop out for 4 s every 8 s (an intermittent device connection)",
}
BASIC_FAULTS = ("crash", "hang", "degrade", "cpu", "leak", "delay", "errlog", "diag")  # every robot has these


@dataclass(frozen=True)
class FaultSpec:
    """A fault to inject: kind ``fault`` into node ``target`` (fqn or ``node:/..``), ``at`` s after start."""

    fault: str
    target: str
    at: float = 5.0

    def __post_init__(self) -> None:
        if self.fault not in FAULTS:
            raise DemoError(f"unknown fault {self.fault!r}; valid faults: {', '.join(FAULTS)}")
        target = self.target.removeprefix("node:")
        if not target.startswith("/"):
            target = "/" + target
        object.__setattr__(self, "target", target)
        if not isinstance(self.at, int | float) or self.at < 0:
            raise DemoError(f"fault time must be a number of seconds >= 0, got {self.at!r}")

    def check(self, nodes: list[str]) -> None:
        """Raise DemoError unless the target is one of ``nodes`` (fqns)."""
        if self.target not in nodes:
            raise DemoError(f"unknown fault target {self.target!r}; valid targets: {', '.join(nodes)}")
