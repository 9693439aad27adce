"""What ran on what: the code's commit and the machine, recorded with every run and every result."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[2]


def code_version(root: Path = ROOT) -> dict:
    """``{"commit": full sha or None, "dirty": uncommitted changes to tracked files}`` of ``root``."""
    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return out.stdout.strip() if out.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit, "dirty": bool(status) if status is not None else None}


def short_version(root: Path = ROOT) -> str:
    """``code_version`` as a label: the short commit, ``-dirty`` with uncommitted changes to
    tracked files, ``unknown`` outside git."""
    v = code_version(root)
    if not v["commit"]:
        return "unknown"
    return v["commit"][:7] + ("-dirty" if v["dirty"] else "")


def machine() -> dict:
    """Cores, CPU model, RAM, OS and Python of this machine."""
    model = platform.processor() or None
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.partition(":")[2].strip()
                break
    except OSError:
        pass
    return {
        "cores": os.cpu_count(),
        "cpu": model,
        "ram_gb": round(psutil.virtual_memory().total / 2**30, 1),
        "os": f"{platform.system()} {platform.release()}",
        "python": sys.version.split()[0],
        "ros_distro": os.environ.get("ROS_DISTRO"),
    }
