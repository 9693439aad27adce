"""Shared pieces of the robustness tests: the real ``stream-viz`` command, small ROS children."""

from __future__ import annotations

import json
import sqlite3
import subprocess
from pathlib import Path
from typing import Any

from stream_viz.collect.cgroups import parse_mountinfo
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


class _Group:
    """A cgroup made for a test: ``add(pid)`` moves a process into it; ``close()`` moves what is
    left out and removes it."""

    dirs: list[Path]

    def add(self, pid: int) -> None:
        for d in self.dirs:
            (d / "cgroup.procs").write_text(str(pid))

    def close(self) -> None:
        for d in self.dirs:
            for pid in (d / "cgroup.procs").read_text().split():
                try:
                    (d.parent / "cgroup.procs").write_text(pid)
                except OSError:
                    continue  # gone meanwhile
            d.rmdir()


def _hierarchies() -> tuple[list, dict]:
    with open("/proc/self/mountinfo") as f:
        mounts = parse_mountinfo(f.read())
    return [m for m in mounts if "" in m.controllers], {c: m for m in mounts for c in m.controllers if c}


class MemoryLimitGroup(_Group):
    """A cgroup whose memory is limited to ``limit`` bytes, as ``docker --memory`` makes one: in v1's
    memory hierarchy where there is one, else in v2 (``memory.max``, no swap). Raises OSError where
    it cannot be made."""

    def __init__(self, limit: int, name: str) -> None:
        v2, v1 = _hierarchies()
        if "memory" in v1:
            d = Path(v1["memory"].point, name)
            d.mkdir()
            self.dirs = [d]
            (d / "memory.limit_in_bytes").write_text(str(limit))
        elif v2 and "memory" in Path(v2[0].point, "cgroup.controllers").read_text().split():
            top = Path(v2[0].point)
            (top / "cgroup.subtree_control").write_text("+memory")
            d = top / name
            d.mkdir()
            self.dirs = [d]
            (d / "memory.max").write_text(str(limit))
            if (d / "memory.swap.max").exists():
                (d / "memory.swap.max").write_text("0")
        else:
            raise OSError("no cgroup hierarchy with the memory controller")


class QuotaGroup(_Group):
    """A cgroup with a CPU quota of ``cpus``, as a container runtime makes one (``docker --cpus``):
    in cgroup v2 (``cpu.max``) where its cpu controller is, else in v1 (``cpu`` and ``cpuacct``).
    Raises OSError where cgroups cannot be made (not root, no cpu controller)."""

    def __init__(self, cpus: float, name: str) -> None:
        v2, v1 = _hierarchies()
        self.dirs: list[Path] = []
        period = 100000
        if "cpu" in v1:
            for c in ("cpu", "cpuacct"):
                if c in v1 and Path(v1[c].point, name) not in self.dirs:
                    d = Path(v1[c].point, name)
                    d.mkdir()
                    self.dirs.append(d)
            (self.dirs[0] / "cpu.cfs_quota_us").write_text(str(int(cpus * period)))
        elif v2 and "cpu" in Path(v2[0].point, "cgroup.controllers").read_text().split():
            top = Path(v2[0].point)
            (top / "cgroup.subtree_control").write_text("+cpu")
            d = top / name
            d.mkdir()
            self.dirs.append(d)
            (d / "cpu.max").write_text(f"{int(cpus * period)} {period}")
        else:
            raise OSError("no cgroup hierarchy with the cpu controller")
