"""Shared pieces of the robustness tests: the real ``stream-viz`` command, small ROS children."""

from __future__ import annotations

import json
import sqlite3
import subprocess
from pathlib import Path
from typing import Any

from stream_viz.testing import EXE

# A node that logs an ERROR on /rosout every 0.5 s (the rosout plugin alerts on it).
ERROR_LOGGER = """
import rclpy
rclpy.init()
n = rclpy.create_node("grumpy")
k = [0]
def tick():
    k[0] += 1
    n.get_logger().error(f"lost the device ({k[0]})")
n.create_timer(0.5, tick)
try:
    rclpy.spin(n)
except (KeyboardInterrupt, Exception):
    pass
"""


def monitor_cmd(*args: str) -> list[str]:
    """``stream-viz monitor --viewer none`` plus ``args``."""
    return [EXE, "monitor", "--viewer", "none", *args]


def run(cmd: list[str], env: dict[str, str], timeout: float = 180, cwd: Path | None = None
        ) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout, cwd=cwd)


def error_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("Error: ")]


def db_rows(db: Path, sql: str, args: tuple = ()) -> list[tuple[Any, ...]]:
    """Rows of a query on a real alert database ([] while the file or table is not there yet)."""
    try:
        with sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True, timeout=5) as con:
            return con.execute(sql, args).fetchall()
    except sqlite3.Error:
        return []


def snapshot_has(db: Path, member: str) -> bool:
    return any(member in r[0] for r in db_rows(db, "SELECT model FROM snapshots"))


def report(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())


def sample_times(rrd: Path) -> list[int]:
    """Distinct ``time`` stamps (ns) under ``/metrics`` of a recording: every sample is logged there."""
    from rerun.chunk import RrdReader

    stamps: set[int] = set()
    for chunk in RrdReader(str(rrd)).stream():
        if not chunk.entity_path.startswith("/metrics"):
            continue
        rb = chunk.to_record_batch()
        if "time" in rb.schema.names:
            col = rb.column(rb.schema.names.index("time")).cast("int64")
            stamps.update(v for v in col.to_pylist() if v is not None)
    return sorted(stamps)
