"""``stream-viz replay`` end to end: a real demo run recorded with ``--samples``, replayed, gives the
live diagnosis; a killed monitor's samples file replays up to its last sample; bad files say so."""

from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import time

import pytest

from stream_viz.testing import EXE, TALKER, wait_for
from tests.cli.test_cli import check_report, leftovers, run_cli

pytestmark = pytest.mark.ros


@pytest.mark.slow
@pytest.mark.parametrize("fault", ["crash", "errlog"])
def test_a_replayed_demo_run_gives_the_live_diagnosis(ros_domain, tmp_path, fault):
    env = dict(os.environ)
    samples, live, again = tmp_path / "s.jsonl.gz", tmp_path / "live.json", tmp_path / "replay.json"
    out = run_cli(["demo", "--fault", fault, "--at", "8", "--duration", "24", "--viewer", "none",
                   "--domain", str(ros_domain), "--report", str(live), "--db", str(tmp_path / "live.sqlite"),
                   "--samples", str(samples), "--save", str(tmp_path / "live.rrd")], env)
    assert out.returncode == 0, out.stderr
    assert leftovers(ros_domain) == []
    live_report = json.loads(live.read_text())
    assert live_report["alerts"] and live_report["root_causes"], live_report["alerts"]
    out = run_cli(["replay", str(samples), "--report", str(again), "--db", str(tmp_path / "replay.sqlite"),
                   "--save", str(tmp_path / "replay.rrd")], env)
    assert out.returncode == 0, out.stderr
    replayed = json.loads(again.read_text())
    check_report(replayed)
    # The same run: every alert, iteration and ranked root cause, the members seen, the fault.
    assert replayed == live_report
    assert f"1. {live_report['root_causes'][0]['member']}" in out.stderr
    assert (tmp_path / "replay.rrd").stat().st_size > 0


def test_replay_at_speed_one_takes_the_runs_time(tmp_path):
    from tests.unit.test_samples_file import _gone_run, write_file

    path = write_file(tmp_path / "s.jsonl.gz", _gone_run()[:6])  # 5 s of samples
    timed = {}
    for speed in ("1", "0"):
        t0 = time.monotonic()
        out = run_cli(["replay", str(path), "--speed", speed, "--db", str(tmp_path / f"{speed}.sqlite")],
                      dict(os.environ))
        timed[speed] = time.monotonic() - t0
        assert out.returncode == 0, out.stderr
    assert timed["1"] - timed["0"] > 4.0, timed


def test_a_killed_monitors_samples_replay_to_their_last_sample(children, tmp_path):
    children.python(TALKER, name="talker")
    samples = tmp_path / "s.jsonl.gz"
    p = subprocess.Popen([EXE, "monitor", "--viewer", "none", "--samples", str(samples),
                          "--db", str(tmp_path / "m.sqlite")], env=children.env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # 5 samples, the talker in them (a cold start may take seconds to discover it)
        wait_for(lambda: samples.exists() and len(lines := _lines(samples)) >= 5
                 and any("/talker" in ln for ln in lines[1:]), timeout=60, period=0.5)
        p.send_signal(signal.SIGKILL)
        p.wait(10)
    finally:
        p.kill()
    out = run_cli(["replay", str(samples), "--report", str(tmp_path / "r.json"),
                   "--db", str(tmp_path / "r.sqlite")], children.env)
    assert out.returncode == 0, out.stderr
    assert "ends mid-way" in out.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert "node:/talker" in {m["id"] for m in report["members"]}


def _lines(path) -> list[str]:
    """Complete lines of a gzip file still being written (it has no end yet)."""
    out = []
    with gzip.open(path, "rt") as f:
        try:
            for line in f:
                if line.endswith("\n"):
                    out.append(line)
        except EOFError:
            pass
    return out


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "missing.jsonl.gz: cannot read the samples file"),
        (b"hello\n", "line 1: not a stream-viz samples file"),
        (b'{"format": "stream-viz.samples/v1"}\n{"t": 1}\n{"t": "x"}\n', "line 3: not a sample record"),
    ],
)
def test_bad_samples_files_give_one_error_line(tmp_path, content, message):
    path = tmp_path / ("missing.jsonl.gz" if content is None else "bad.jsonl.gz")
    if content is not None:
        path.write_bytes(content)
    out = run_cli(["replay", str(path), "--db", str(tmp_path / "r.sqlite")], dict(os.environ), timeout=60)
    assert out.returncode == 2
    lines = [ln for ln in out.stderr.splitlines() if ln.startswith("Error: ")]
    assert len(lines) == 1 and message in lines[0] and str(path) in lines[0], out.stderr
    assert "Traceback" not in out.stderr
