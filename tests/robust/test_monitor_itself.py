"""The monitor process itself: SIGKILL loses nothing committed, a vanishing viewer does not stop
it, and it only observes (checked from the ROS graph by an independent rclpy observer).

SIGINT/SIGTERM (report written, exit 0) is tested in tests/cli/test_cli.py.
"""

from __future__ import annotations

import ctypes.util
import os
import signal
import socket
import subprocess
import time

import pytest

from stream_viz.collect.fastdds import decode_gid
from stream_viz.testing import EXE, TALKER, wait_for
from tests.robust.common import (
    ERROR_LOGGER,
    db_rows,
    error_lines,
    monitor_cmd,
    report,
    run,
    sample_times,
    snapshot_has,
)


def _rosout_alerts(db) -> list[tuple]:
    return db_rows(db, "SELECT id, member, t, message FROM alerts WHERE plugin = 'rosout' ORDER BY id")


@pytest.mark.ros
def test_sigkill_loses_no_committed_alert_and_the_database_reopens(children, tmp_path):
    children.python(ERROR_LOGGER, name="grumpy")
    db = tmp_path / "a.sqlite"
    # 1) killed very early, while the database is being created and the observer starts.
    p = children.run(monitor_cmd("--db", str(db)), name="monitor_early")
    wait_for(lambda: db.exists(), timeout=30, period=0.05)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(10)
    # 2) it opens again fine and goes on collecting; killed mid-run with alerts committed.
    p = children.run(monitor_cmd("--db", str(db)), name="monitor_mid")
    wait_for(lambda: len(_rosout_alerts(db)) >= 3, timeout=60, period=0.2)
    committed = _rosout_alerts(db)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(10)
    after = _rosout_alerts(db)
    assert after[: len(committed)] == committed  # every row seen committed before the kill is there
    assert db_rows(db, "PRAGMA integrity_check") == [("ok",)]
    # 3) analyze works on the killed run's file; a new monitor run on it is refused, as it would
    # mix its alerts with the killed run's, and leaves every row.
    out = run([EXE, "analyze", "--db", str(db), "--report", str(tmp_path / "off.json")], children.env)
    assert out.returncode == 0, out.stderr
    assert "node:/grumpy" in {a["member"] for a in report(tmp_path / "off.json")["alerts"]}
    out = run(monitor_cmd("--db", str(db), "--duration", "4"), children.env)
    lines = error_lines(out.stderr)
    assert out.returncode != 0 and len(lines) == 1 and "a.sqlite: already holds a run" in lines[0], out.stderr
    assert _rosout_alerts(db) == after


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.mark.ros
def test_a_viewer_that_goes_away_does_not_stop_monitoring_or_the_rrd(children, tmp_path):
    from stream_viz.viz.screenshot import rerun_executable

    exe = rerun_executable()
    if exe is None or ctypes.util.find_library("vulkan") is None:
        pytest.skip("needs the rerun viewer and a Vulkan loader to run a viewer to connect to")
    children.python(TALKER, name="talker")
    port = _free_port()
    viewer = children.run([exe, "--headless", "--hide-welcome-screen", f"--port={port}"], name="viewer",
                          env=dict(children.env, CI="1"))
    wait_for(lambda: _listening(port), timeout=30, period=0.2)
    rrd, db, rep = tmp_path / "m.rrd", tmp_path / "a.sqlite", tmp_path / "r.json"
    log = open(tmp_path / "monitor.log", "w")
    p = subprocess.Popen([EXE, "monitor", "--viewer", f"rerun+http://127.0.0.1:{port}/proxy", "--save",
                          str(rrd), "--db", str(db), "--report", str(rep)], env=children.env,
                         stdout=log, stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: snapshot_has(db, "node:/talker"), timeout=60, period=0.3)
        time.sleep(2.0)  # a few samples streamed to the viewer
        os.killpg(viewer.pid, signal.SIGKILL)  # the viewer (and its real binary) gone at once
        viewer.wait(10)
        t_kill = time.time()
        time.sleep(5.0)  # the monitor keeps sampling with nobody listening
        assert p.poll() is None, (tmp_path / "monitor.log").read_text()
        p.send_signal(signal.SIGINT)
        code = p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
    text = (tmp_path / "monitor.log").read_text()
    assert code == 0, text
    assert "Traceback" not in text
    assert "node:/talker" in {m["id"] for m in report(rep)["members"]}
    stamps = sample_times(rrd)  # reading needs the footer: the file was closed properly
    after = [s for s in stamps if s / 1e9 > t_kill + 1.0]
    assert len(after) >= 2, (len(stamps), t_kill)


@pytest.mark.ros
def test_the_monitor_only_subscribes(children, tmp_path, ros_domain):
    """An independent observer lists what the monitor's process has in the ROS graph."""
    import rclpy
    from rclpy.action import (
        get_action_client_names_and_types_by_node,
        get_action_server_names_and_types_by_node,
    )
    from rclpy.context import Context

    children.python(TALKER, name="talker")
    db = tmp_path / "a.sqlite"
    mon = children.run(monitor_cmd("--db", str(db), "--duration", "40"), name="monitor")
    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    try:
        me = rclpy.create_node("_robust_checker", context=ctx, enable_rosout=False,
                               start_parameter_services=False)
        wait_for(lambda: snapshot_has(db, "node:/talker"), timeout=60, period=0.3)
        time.sleep(3.0)  # the monitor has subscribed to every topic by now
        own = f"_stream_viz_observer_{mon.pid}"
        names = me.get_node_names_and_namespaces()
        assert (own, "/") in names, names
        assert mon.poll() is None
        pubs = me.get_publisher_names_and_types_by_node(own, "/")
        servers = me.get_service_names_and_types_by_node(own, "/")
        clients = me.get_client_names_and_types_by_node(own, "/")
        action_clients = get_action_client_names_and_types_by_node(me, own, "/")
        action_servers = get_action_server_names_and_types_by_node(me, own, "/")
        subs = dict(me.get_subscriber_names_and_types_by_node(own, "/"))
        # Any endpoint of any node in the monitor's process (Fast DDS gid carries the pid).
        low16 = mon.pid & 0xFFFF
        foreign_pubs = []
        for topic, _ in me.get_topic_names_and_types():
            for info in me.get_publishers_info_by_topic(topic):
                g = decode_gid(bytes(info.endpoint_gid))
                if g is not None and g.pid_low16 == low16:
                    foreign_pubs.append((topic, info.node_name))
        extra_nodes = sorted(n for n, _ in names if n not in ("talker", "listener", "_robust_checker", own))
    finally:
        ctx.try_shutdown()
    assert pubs == [], pubs
    assert servers == [], servers
    assert clients == [], clients
    assert action_clients == [] and action_servers == []
    assert foreign_pubs == []
    assert extra_nodes == []  # the monitor made no other node
    assert {"/rosout", "/diagnostics", "/chatter"} <= set(subs)  # it does watch, through subscriptions
