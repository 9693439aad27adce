"""Bad inputs to the real command: one ``Error: …`` line naming what and where, exit non-zero,
nothing of the user's touched. (Missing config/db, a wrong-typed key, an .rrd in a missing folder
and analyze on an empty database are in tests/cli/test_cli.py.)"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess

import pytest

from stream_viz.detect.store import AlertStore
from stream_viz.records import Alert
from stream_viz.testing import EXE, wait_for
from tests.robust.common import ERROR_LOGGER, db_rows, error_lines, monitor_cmd, report, run


def _files(tmp):
    (tmp / "corrupt.sqlite").write_bytes(b"SQLite format 3\x00" + os.urandom(4096))
    (tmp / "random.sqlite").write_bytes(os.urandom(8192))
    with sqlite3.connect(tmp / "foreign.sqlite") as con:
        con.execute("CREATE TABLE users (id INTEGER PRIMARY KEY, name TEXT)")
        con.execute("INSERT INTO users (name) VALUES ('ada')")
    con.close()
    (tmp / "unknown_key.toml").write_text("[monitor]\nperiod = 1.0\nperiode = 2.0\n")
    (tmp / "unknown_section.toml").write_text("[monitorr]\nperiod = 1.0\n")
    (tmp / "malformed.toml").write_text("[monitor\nperiod = \n")
    (tmp / "plugin_key.toml").write_text("[plugins.topic_rate]\nno_such_setting = 1\n")
    (tmp / "a_folder.rrd").mkdir()
    (tmp / "plain_file").write_text("x")
    (tmp / "zero.sqlite").write_bytes(b"")
    with AlertStore(tmp / "used.sqlite") as st:  # a database that holds a run already
        st.begin_run(1.0)
        st.add([Alert("node:/cam", "rosout", 2.0, "error", "boom")])


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["monitor", "--db", "{tmp}/corrupt.sqlite"], ["corrupt.sqlite"]),
        (["monitor", "--db", "{tmp}/random.sqlite"], ["random.sqlite"]),
        (["monitor", "--db", "{tmp}/foreign.sqlite"], ["foreign.sqlite", "another program"]),
        (["monitor", "--db", "{tmp}/used.sqlite"], ["used.sqlite", "already holds a run"]),
        (["monitor", "--report", "{tmp}/no/such/dir/r.json"], ["no/such/dir"]),
        (["monitor", "--report", "{tmp}/plain_file/r.json"], ["plain_file"]),
        (["monitor", "--save", "{tmp}/a_folder.rrd"], ["a_folder.rrd"]),
        (["monitor", "--save", "{tmp}/plain_file/m.rrd"], ["plain_file"]),
        (["monitor", "--config", "{tmp}/unknown_key.toml"], ["unknown_key.toml", "periode"]),
        (["monitor", "--config", "{tmp}/unknown_section.toml"], ["unknown_section.toml", "monitorr"]),
        (["monitor", "--config", "{tmp}/malformed.toml"], ["malformed.toml", "malformed TOML"]),
        (["monitor", "--config", "{tmp}/plugin_key.toml"], ["plugin_key.toml", "no_such_setting"]),
        (["analyze", "--db", "{tmp}/corrupt.sqlite"], ["corrupt.sqlite"]),
        (["analyze", "--db", "{tmp}/foreign.sqlite"], ["foreign.sqlite"]),
        (["analyze", "--db", "{tmp}/zero.sqlite"], ["zero.sqlite"]),
    ],
)
def test_bad_input_gives_one_error_naming_it_and_touches_nothing(ros_domain, tmp_path, args, names):
    _files(tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if args[0] == "monitor":
        args += ["--viewer", "none", "--duration", "2"]
        if "--db" not in args:
            args += ["--db", str(tmp_path / "ok.sqlite")]
    out = run([EXE, *args], dict(os.environ), timeout=60)
    assert out.returncode != 0
    lines = error_lines(out.stderr)
    assert len(lines) == 1, out.stderr
    for n in names:
        assert n in lines[0], out.stderr
    assert "Traceback" not in out.stderr
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file() and p.name in before}
    assert after == before  # the user's files, foreign database included, are left as they were


@pytest.mark.ros
def test_report_folder_removed_mid_run_names_it_and_keeps_the_alerts(children, tmp_path):
    """The report cannot be written at the end: Error naming it, exit non-zero, the DB keeps everything."""
    children.python(ERROR_LOGGER, name="grumpy")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    rep, db = out_dir / "r.json", tmp_path / "a.sqlite"
    log = open(tmp_path / "monitor.log", "w")
    p = subprocess.Popen(monitor_cmd("--db", str(db), "--report", str(rep)), env=children.env,
                         stdout=log, stderr=subprocess.STDOUT)
    try:
        wait_for(lambda: db_rows(db, "SELECT count(*) FROM alerts WHERE plugin='rosout'")[0][0] >= 2
                 if db_rows(db, "SELECT count(*) FROM alerts") else False, timeout=60, period=0.5)
        out_dir.rmdir()
        p.send_signal(signal.SIGINT)
        code = p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
    text = (tmp_path / "monitor.log").read_text()
    assert code != 0
    lines = error_lines(text)
    assert len(lines) == 1 and "r.json" in lines[0], text
    alerts = db_rows(db, "SELECT member FROM alerts WHERE plugin='rosout'")
    assert len(alerts) >= 2 and {a[0] for a in alerts} == {"node:/grumpy"}
    assert db_rows(db, "SELECT value FROM meta WHERE key='ended_at'")  # closed properly all the same
    a = run([EXE, "analyze", "--db", str(db), "--report", str(tmp_path / "offline.json")], children.env)
    assert a.returncode == 0, a.stderr
    assert any(x["member"] == "node:/grumpy" for x in report(tmp_path / "offline.json")["alerts"])
