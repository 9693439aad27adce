"""θ: one numpy attribute vector per member, with a named schema per member kind."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stream_viz.errors import ModelError

# Names are what a person reads in the viewer; units are in the names.
SCHEMAS: dict[str, tuple[str, ...]] = {
    "process": (
        "cpu_percent", "rss_mb", "threads", "ctx_switches_per_s", "open_files",
        "io_read_kBps", "io_write_kBps", "running_threads",
        "executor_cpu_percent", "main_cpu_percent", "dispatching",
    ),
    "topic": (
        "rate_hz", "jitter_ms", "latency_ms", "bandwidth_kBps", "drops_per_s",
        "publishers", "subscribers", "rate_recent_hz", "age_s", "stamp_age_ms",
        "gap_s", "sim_pace", "stamp_age_recent_ms",
    ),
    "node": ("publishers", "subscriptions", "services", "clients", "sent_hz"),
    "service": ("servers", "clients", "calls_per_s", "response_ms", "waiting", "wait_s"),
    "action": ("servers", "clients"),
    "host": ("cpu_percent", "rss_mb", "threads", "ctx_switches_per_s", "open_files",
             "io_read_kBps", "io_write_kBps", "machine_cpu_percent", "machine_mem_percent",
             "cpu_pressure_percent"),
    "root": ("cpu_percent", "rss_mb", "threads", "ctx_switches_per_s", "open_files",
             "io_read_kBps", "io_write_kBps"),
}


def make_theta(kind: str, values: Mapping[str, float]) -> np.ndarray:
    """Return θ for a member of ``kind`` from named values; unknown values are NaN.

    Parameters
    ----------
    kind : str
        The member kind, a key of ``SCHEMAS``.
    values : mapping
        Attribute name to value; a name outside the schema is an error.
    """
    schema = SCHEMAS.get(kind)
    if schema is None:
        raise ModelError(f"no θ schema for member kind {kind!r}")
    extra = set(values) - set(schema)
    if extra:
        raise ModelError(f"θ of a {kind}: unknown attributes {sorted(extra)}")
    return np.array([float(values.get(name, np.nan)) for name in schema])


def theta_dict(kind: str, theta: np.ndarray) -> dict[str, float]:
    """Return θ as a name → value dict (the inverse of `make_theta`)."""
    return dict(zip(SCHEMAS[kind], (float(x) for x in theta), strict=True))
