"""The command line end to end, as a user runs it: real robot processes, real files read back."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import jsonschema
import psutil
import pytest
from rerun.chunk import RrdReader

from stream_viz.testing import EXE, TALKER, wait_for
from tests.viz.rrd import rows, shown

REPORT_SCHEMA = jsonschema.Draft202012Validator(
    json.loads((Path(__file__).resolve().parents[2] / "docs" / "report.schema.json").read_text()))


def run_cli(args: list[str], env: dict[str, str], timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([EXE, *args], env=env, capture_output=True, text=True, timeout=timeout)


def check_report(report: dict) -> None:
    """The report contract of docs/contracts.md (every field checked by docs/report.schema.json)."""
    REPORT_SCHEMA.validate(report)
    assert report["schema"] == "stream-viz.report/v2"
    assert report["ended_at"] >= report["started_at"] > 1e9
    for m in report["members"]:
        assert set(m) >= {"id", "kind"}
        if m["kind"] == "node":
            assert "pid" in m
    for e in report["edges"]:
        assert e["kind"] in ("pub", "sub", "send")
    for a in report["alerts"]:
        assert set(a) >= {"member", "plugin", "severity", "t", "message"}
    for it in report["iterations"]:
        assert set(it) >= {"j", "t", "subgraph", "watchlist"}
    scores = [rc["score"] for rc in report["root_causes"]]
    assert scores == sorted(scores, reverse=True)
    for rc in report["root_causes"]:
        assert rc["trajectory"][-1] == rc["member"]


def leftovers(domain: int) -> list[int]:
    """Processes of the demo robot still running on ``domain``."""
    out = []
    for p in psutil.process_iter(["cmdline"]):
        try:
            if "stream_viz.demo.robot_process" in " ".join(p.info["cmdline"] or []) and \
                    p.environ().get("ROS_DOMAIN_ID") == str(domain):
                out.append(p.pid)
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            pass
    return out


@pytest.mark.ros
@pytest.mark.slow
def test_demo_end_to_end_ranks_the_injected_node_first(ros_domain, tmp_path):
    env = dict(os.environ)
    rep, db, rrd = tmp_path / "r.json", tmp_path / "a.sqlite", tmp_path / "d.rrd"
    out = run_cli(["demo", "--fault", "crash", "--target", "/lidar_driver", "--at", "12", "--duration", "32",
                   "--viewer", "none", "--domain", str(ros_domain), "--report", str(rep), "--db", str(db),
                   "--save", str(rrd)], env)
    assert out.returncode == 0, out.stderr
    report = json.loads(rep.read_text())
    check_report(report)
    assert report["injected"]["fault"] == "crash"
    assert report["injected"]["target"] == "node:/lidar_driver"
    assert report["root_causes"][0]["member"] == "node:/lidar_driver", report["root_causes"][:3]
    assert "1. node:/lidar_driver" in out.stderr
    nodes = {m["id"] for m in report["members"] if m["kind"] == "node"}
    assert len(nodes) >= 10
    assert {"src": "node:/lidar_driver", "dst": "topic:/scan", "kind": "pub"} in report["edges"]
    assert any(a["member"] == "node:/lidar_driver" and a["plugin"] == "member_gone" for a in report["alerts"])
    paths = set(RrdReader(str(rrd)).store().schema().entity_paths())
    for p in ("/system", "/process_tree", "/alerts", "/rca/subgraph", "/rca/trajectory", "/rca/report"):
        assert p in paths, sorted(paths)
    assert any(p.startswith("/metrics/") for p in paths)
    assert leftovers(ros_domain) == []
    # The saved database reproduces the diagnosis offline.
    out = run_cli(["analyze", "--db", str(db), "--report", str(tmp_path / "a.json")], env)
    assert out.returncode == 0, out.stderr
    offline = json.loads((tmp_path / "a.json").read_text())
    check_report(offline)
    assert offline["root_causes"][0]["member"] == "node:/lidar_driver"
    assert out.stdout.startswith("1. node:/lidar_driver")


@pytest.mark.ros
def test_monitor_ends_on_duration_and_writes_everything(children, tmp_path):
    children.python(TALKER, name="talker")
    rep, db = tmp_path / "r.json", tmp_path / "a.sqlite"
    out = run_cli(["monitor", "--duration", "6", "--viewer", "none", "--report", str(rep), "--db", str(db),
                   "--save", str(tmp_path / "m.rrd")], children.env)
    assert out.returncode == 0, out.stderr
    report = json.loads(rep.read_text())
    check_report(report)
    ids = {m["id"] for m in report["members"]}
    assert {"node:/talker", "node:/listener", "topic:/chatter"} <= ids
    assert {"src": "topic:/chatter", "dst": "node:/listener", "kind": "sub"} in report["edges"]
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT count(*) FROM snapshots").fetchone()[0] >= 1
    assert "/system" in RrdReader(str(tmp_path / "m.rrd")).store().schema().entity_paths()


@pytest.mark.ros
def test_monitor_group_by_process_draws_a_box_around_each_process(children, tmp_path):
    talker = children.python(TALKER, name="talker")  # /talker and /listener in one process
    out = run_cli(["monitor", "--duration", "8", "--viewer", "none", "--group-by", "process",
                   "--save", str(tmp_path / "m.rrd")], children.env)
    assert out.returncode == 0, out.stderr
    data = rows(tmp_path / "m.rrd")
    system = shown(data["/system"])  # rows log only the fields that changed: what the viewer shows
    pos = dict(zip(system["GraphNodes:node_ids"], map(tuple, system["GraphNodes:positions"]), strict=True))
    boxes = {path: row["GraphNodes:positions"] for path, found in data.items() if path.startswith("/process/")
             for row in found[-1:] if row.get("GraphNodes:positions")}
    assert boxes and not any(path.startswith("/namespace/") for path in data)
    (x0, y0), (x1, y1) = next(iter(boxes.values()))
    for node in ("node:/talker", "node:/listener"):
        assert x0 < pos[node][0] < x1 and y0 < pos[node][1] < y1, (node, pos, boxes)
    assert talker.poll() is None


@pytest.mark.ros
def test_a_long_monitor_run_saves_its_recording_in_parts(children, tmp_path):
    children.python(TALKER, name="talker")
    cfg = tmp_path / "c.toml"
    cfg.write_text("[monitor]\nrecording_part_minutes = 0.05\n")  # a part every 3 s
    rrd = tmp_path / "m.rrd"
    out = run_cli(["monitor", "--duration", "8", "--config", str(cfg), "--db", str(tmp_path / "a.sqlite"),
                   "--save", str(rrd)], children.env)
    assert out.returncode == 0, out.stderr
    parts = sorted(tmp_path.glob("m*.rrd"))
    assert [p.name for p in parts][:2] == ["m.rrd", "m_1.rrd"] and len(parts) >= 2
    assert f"in {len(parts)} parts" in out.stderr and str(tmp_path / "m_1.rrd") in out.stderr
    recordings = set()
    for p in parts:  # each part is a closed file with the system graph, all one recording
        reader = RrdReader(str(p))
        assert "/system" in reader.store().schema().entity_paths(), p
        recordings |= {e.recording_id for e in reader.recordings()}
    assert len(recordings) == 1


@pytest.mark.ros
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_monitor_ends_on_a_signal_and_writes_the_report(children, tmp_path, sig):
    children.python(TALKER, name="talker")
    rep, db = tmp_path / "r.json", tmp_path / "a.sqlite"
    log = open(tmp_path / "monitor.log", "w")
    p = subprocess.Popen([EXE, "monitor", "--viewer", "none", "--report", str(rep), "--db", str(db)],
                         env=children.env, stdout=log, stderr=subprocess.STDOUT)
    try:
        def sees_talker() -> bool:
            try:
                with sqlite3.connect(db) as con:
                    rows = con.execute("SELECT model FROM snapshots").fetchall()
            except sqlite3.Error:  # not created yet
                return False
            return any("node:/talker" in r[0] for r in rows)

        wait_for(sees_talker, timeout=30, period=0.3)
        start = time.monotonic()
        p.send_signal(sig)
        assert p.wait(15) == 0, (tmp_path / "monitor.log").read_text()
        took = time.monotonic() - start
    finally:
        if p.poll() is None:
            p.kill()
    report = json.loads(rep.read_text())
    check_report(report)
    assert "node:/talker" in {m["id"] for m in report["members"]}
    assert took < 15


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["demo", "--target", "/no_such_node", "--duration", "5"], "unknown fault target '/no_such_node'"),
        (["demo", "--fault", "crash", "--size", "2", "--duration", "5"], "'crash' takes no size"),
        (["demo", "--fault", "degrade", "--size", "1.5", "--duration", "5"], "bad size 1.5 for degrade"),
        (["demo", "--config", "{tmp}/missing.toml", "--duration", "5"], "missing.toml"),
        (["demo", "--report", "{tmp}/no/such/dir/r.json", "--duration", "5"], "no/such/dir"),
        (["monitor", "--save", "{tmp}/no/such/dir/m.rrd", "--duration", "2"], "no/such/dir"),
        (["monitor", "--config", "{tmp}/bad.toml", "--duration", "2"], "bad.toml"),
        (["analyze", "--db", "{tmp}/missing.sqlite"], "missing.sqlite"),
        (["analyze", "--db", "{tmp}/empty.sqlite"], "empty.sqlite"),
    ],
)
def test_bad_arguments_give_one_error_line_and_leave_nothing_running(ros_domain, tmp_path, args, message):
    (tmp_path / "bad.toml").write_text("[monitor]\nperiod = 'fast'\n")
    # An alert database of ours with nothing in it (a monitor that never saw anything).
    from stream_viz.detect.store import AlertStore

    AlertStore(tmp_path / "empty.sqlite").close()
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain))
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    out = run_cli([*args, "--viewer", "none"] if args[0] != "analyze" else args, env, timeout=60)
    assert out.returncode != 0
    lines = [ln for ln in out.stderr.splitlines() if ln.startswith("Error: ")]
    assert len(lines) == 1 and message in lines[0], out.stderr
    assert "Traceback" not in out.stderr
    assert leftovers(ros_domain) == []


@pytest.mark.ros
def test_snapshot_prints_the_model_as_json_and_text(children):
    talker = children.python(TALKER, name="talker")

    def snapshot():  # a loaded machine may take longer than one settle to start the talker
        out = run_cli(["snapshot", "--json", "--settle", "3"], children.env, timeout=60)
        assert out.returncode == 0, out.stderr
        data = json.loads(out.stdout)
        members = {m["id"]: m for m in data["members"]}
        edges = {(e["src"], e["dst"], e["kind"]) for e in data["edges"]}
        flow = {("node:/talker", "topic:/chatter", "pub"), ("topic:/chatter", "node:/listener", "sub")}
        names = ("node:/talker", "node:/listener")  # their pids and endpoints can come later
        ok = all(members.get(n, {}).get("pid") for n in names) and flow <= edges
        return (data, members) if ok else None

    data, members = wait_for(snapshot, timeout=90, period=0.5)
    assert members["node:/talker"]["pid"] == talker.pid == members["node:/listener"]["pid"]
    assert f"process:{talker.pid}" in members
    edges = {(e["src"], e["dst"], e["kind"]) for e in data["edges"]}
    assert {("node:/talker", "topic:/chatter", "pub"), ("topic:/chatter", "node:/listener", "sub"),
            (f"process:{talker.pid}", "node:/talker", "tree")} <= edges
    text = run_cli(["snapshot", "--settle", "3"], children.env, timeout=60)
    assert text.returncode == 0 and "/talker" in text.stdout and "/chatter" in text.stdout
