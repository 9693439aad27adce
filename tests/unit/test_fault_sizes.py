"""Fault sizes: FaultSpec.size validation, the degrade spread, and the process-wide faults' sizes."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from stream_viz.demo.child import WATCHDOG, burn, errlog, next_fault, parser, record_injection
from stream_viz.demo.faults import SIZES, FaultSpec, keeps
from stream_viz.errors import DemoError


def test_a_fault_spec_takes_a_size_for_the_sized_kinds_only():
    assert FaultSpec("degrade", "/lidar_driver", 1.0).size is None  # the kind's default
    assert FaultSpec("degrade", "/lidar_driver", 1.0, size=0.7).size == 0.7
    assert FaultSpec("leak", "/map_server", size=1).size == 1
    assert FaultSpec("delay", "/amr1/front_lidar", size=20.0).size == 20.0
    assert FaultSpec("errlog", "/controller", size=0.2).size == 0.2
    assert set(SIZES) == {"degrade", "leak", "delay", "cpu", "errlog"}
    with pytest.raises(DemoError, match="'crash' takes no size; sized faults: degrade, leak, delay, cpu"):
        FaultSpec("crash", "/lidar_driver", size=2.0)
    for fault, bad in (("degrade", 1.5), ("degrade", 0), ("cpu", 1.01), ("leak", -1), ("delay", float("nan")),
                       ("errlog", "2"), ("leak", True)):
        with pytest.raises(DemoError, match=f"bad size .* for {fault}"):
            FaultSpec(fault, "/lidar_driver", size=bad)


def test_degrade_keeps_an_even_share_of_the_messages():
    assert [keeps(i, 0.25) for i in range(1, 9)] == [False, False, False, True] * 2  # every 4th, as before
    assert [keeps(i, 0.5) for i in range(1, 7)] == [False, True] * 3
    T, F = True, False
    assert [keeps(i, 0.7) for i in range(1, 11)] == [F, T, T, F, T, T, F, T, T, T]  # 7 of 10, spread
    assert sum(keeps(i, 0.7) for i in range(1, 101)) == 70
    assert all(keeps(i, 1.0) for i in range(1, 20))


def test_the_size_travels_from_the_command_line_and_from_fault_json(tmp_path):
    args = parser("p", "d").parse_args(["--group", "g", "--fault", "leak", "--target", "/a", "--at", "5",
                                        "--size", "2.5"])
    assert next_fault(args, tmp_path) == ("leak", "/a", 5.0, 2.5)
    none = argparse.Namespace(fault=None, target=None, at=None, size=None)
    (tmp_path / "fault.json").write_text(json.dumps({"fault": "cpu", "target": "/b", "at": 7.0, "size": 0.3}))
    assert next_fault(none, tmp_path) == ("cpu", "/b", 7.0, 0.3)
    (tmp_path / "fault.json").write_text(json.dumps({"fault": "hang", "target": "/b", "at": 7.0}))
    assert next_fault(none, tmp_path) == ("hang", "/b", 7.0, None)


def test_the_injection_record_has_the_size_when_there_is_one(tmp_path):
    assert record_injection(tmp_path, "leak", "/a", 1.0)
    rec = json.loads((tmp_path / "injected.json").read_text())
    assert (rec["fault"], rec["target"], rec["size"], rec["pid"]) == ("leak", "node:/a", 1.0, os.getpid())
    assert not record_injection(tmp_path, "leak", "/a", 1.0)  # once per run
    (tmp_path / "injected.json").unlink()
    assert record_injection(tmp_path, "crash", "/a")
    assert "size" not in json.loads((tmp_path / "injected.json").read_text())


class _Logger:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def error(self, text: str) -> None:
        self.lines.append(text)


def _run_for(seconds: float, target, *args) -> None:
    stop = threading.Event()
    t = threading.Thread(target=target, args=(stop, *args))
    t.start()
    time.sleep(seconds)
    stop.set()
    t.join(2.0)


def test_errlog_logs_its_lines_per_second():
    log = _Logger()
    _run_for(1.05, lambda stop: errlog(log, stop, "e{n}", 5.0))
    assert log.lines[:3] == ["e1", "e2", "e3"] and 4 <= len(log.lines) <= 5


def test_a_partial_cpu_fault_burns_about_its_share_of_a_core():
    t0 = time.process_time()
    _run_for(2.0, burn, 0.25)
    used = (time.process_time() - t0) / 2.0
    assert 0.05 < used < 0.4  # at most its share (plus this test's own work); less only on a busy machine


def test_a_demo_process_whose_teardown_holds_the_gil_still_ends(tmp_path):
    """A real child in `end_process` whose teardown spins in C holding the GIL (as Fast DDS's
    participant teardown did in CI, for 33 min at 100 % of a core) still ends, with its stacks."""
    code = textwrap.dedent("""
        import re
        from rclpy.context import Context
        from stream_viz.demo.child import end_process
        ctx = Context()
        ctx.init()
        spin = lambda: re.fullmatch(r"(a+)+b", "a" * 64)  # exponential, in C, the GIL held
        print("ending", flush=True)
        end_process([], [], [spin], ctx)
    """)
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        assert p.stdout.readline() == "ending\n"
        t0 = time.monotonic()
        _, err = p.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 1 and 5.5 < took < 15, (p.returncode, took, err)
    assert WATCHDOG in err and "fullmatch" in err, err
