"""One real evaluation run (`bench.eval.run_one`): demo robot, injected fault, everything it writes."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_a_crash_run_ranks_the_target_and_writes_what_the_peers_need(tmp_path):
    spec = {"system": "demo", "fault": "crash", "target": "/camera_driver", "warmup": 8, "post": 8}
    out = tmp_path / "run"
    proc = subprocess.run(
        [sys.executable, "-m", "bench.eval.run_one", "--spec", json.dumps(spec), "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=240,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    run = json.loads((out / "run.json").read_text())
    assert run["truth_strict"] == ["node:/camera_driver"]
    # the camera process hosts only the camera driver: the live diagnosis names it first
    assert run["rankings"]["live"][0] == "node:/camera_driver"
    assert run["rankings"]["both/trajectory"][0] == "node:/camera_driver"
    assert run["injected"]["target"] == "node:/camera_driver"
    assert 0 <= run["first_alert_s"] < 5
    assert run["alerts_before_injection"] == 0
    assert any(a["member"] == "node:/camera_driver" and a["plugin"] == "member_gone" for a in run["alerts"])
    assert run["alive_at_end"]["camera"] is False
    # the metric table the peers read: a time column and <service>_<metric> columns (one underscore)
    with open(out / "metrics.csv") as f:
        header = next(csv.reader(f))
    assert header[0] == "time" and "node.camera-driver_pubs" in header
    assert all(c.count("_") == 1 for c in header[1:])
    assert (out / "alerts.sqlite").exists()
