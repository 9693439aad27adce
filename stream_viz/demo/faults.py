"""The fault kinds the demo can inject and their validated specification."""

from __future__ import annotations

import math
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

# Kinds that take a size (``FaultSpec.size``): what it measures. Without a size a fault acts as
# described in FAULTS (the defaults below; delay's differs per robot, see `delay_ms`).
SIZES: dict[str, str] = {
    "degrade": "fraction of its messages the target still publishes, 0 < size <= 1 (default 0.25)",
    "leak": "MB allocated per second (default 20)",
    "delay": "extra delay in ms (default: a random 50-400 ms per callback on the demo, 300 ms on the AMR)",
    "cpu": "share of one core burnt, 0 < size <= 1 (default 1)",
    "errlog": "ERROR lines per second (default 2)",
}
DEGRADE_KEEP = 0.25
LEAK_MB_S = 20.0
CPU_SHARE = 1.0
ERRLOG_PER_S = 2.0


@dataclass(frozen=True)
class FaultSpec:
    """A fault to inject: kind ``fault`` into node ``target`` (fqn or ``node:/..``), ``at`` s after start.

    ``size``: how strong, for the kinds in `SIZES` (None: the kind's default, today's behaviour).
    """

    fault: str
    target: str
    at: float = 5.0
    size: float | None = None

    def __post_init__(self) -> None:
        if self.fault not in FAULTS:
            raise DemoError(f"unknown fault {self.fault!r}; valid faults: {', '.join(FAULTS)}")
        target = self.target.removeprefix("node:")
        if not target.startswith("/"):
            target = "/" + target
        object.__setattr__(self, "target", target)
        if not isinstance(self.at, int | float) or self.at < 0:
            raise DemoError(f"fault time must be a number of seconds >= 0, got {self.at!r}")
        if self.size is not None:
            check_size(self.fault, self.size)

    def check(self, nodes: list[str]) -> None:
        """Raise DemoError unless the target is one of ``nodes`` (fqns)."""
        if self.target not in nodes:
            raise DemoError(f"unknown fault target {self.target!r}; valid targets: {', '.join(nodes)}")


def check_size(fault: str, size: object) -> None:
    """Raise DemoError unless ``size`` is a valid size of fault kind ``fault`` (see `SIZES`)."""
    if fault not in SIZES:
        raise DemoError(f"fault {fault!r} takes no size; sized faults: {', '.join(SIZES)}")
    ok = isinstance(size, int | float) and not isinstance(size, bool) and math.isfinite(size) and size > 0
    if not ok or (fault in ("degrade", "cpu") and size > 1):
        raise DemoError(f"bad size {size!r} for {fault}: {SIZES[fault]}")


def keeps(count: int, fraction: float) -> bool:
    """Whether the ``count``-th message (from 1) goes out when only ``fraction`` of them do.

    The kept messages are spread evenly: 0.25 keeps every 4th (the 4th, 8th, ...), 0.5 every 2nd.
    """
    eps = 1e-9  # 0.7 * 10 is 7.000000000000001: floor must not depend on such rounding
    return math.floor(count * fraction + eps) > math.floor((count - 1) * fraction + eps)

