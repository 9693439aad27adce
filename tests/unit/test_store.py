"""The alert database on real SQLite files: round trips, episodes, a SIGKILLed writer, bad files."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from stream_viz.detect.problems import PluginProblem
from stream_viz.detect.store import APP, MIGRATIONS, SCHEMA_VERSION, AlertStore, default_db_path
from stream_viz.errors import StoreError
from stream_viz.model.graph import add_flow_edge, add_member, new_graph
from stream_viz.model.theta import make_theta
from stream_viz.records import Alert


def _graph(extra: bool = False):
    G = new_graph()
    add_member(G, "node:/cam", pid=10)
    add_member(G, "topic:/img", theta=make_theta("topic", {"rate_hz": 10.0}))
    add_flow_edge(G, "node:/cam", "topic:/img", "pub")
    if extra:
        add_member(G, "node:/det", pid=11)
        add_flow_edge(G, "topic:/img", "node:/det", "sub")
    return G


def test_round_trip_and_reopen(tmp_path):
    path = tmp_path / "a.sqlite"
    with AlertStore(path) as st:
        stored = st.add([Alert("topic:/img", "topic_rate", 100.0, "error", "silent", {"silent_s": 1.5}),
                         Alert("node:/cam", "rosout", 101.0, "fatal", "boom")])
        assert len(stored) == 2
        st.set_meta("args", {"duration": 5})
    with AlertStore(path) as st:
        assert st.schema_version == SCHEMA_VERSION
        assert st.get_meta("app") == APP
        assert st.get_meta("args") == {"duration": 5}
        assert st.get_meta("missing", 7) == 7
        assert st.alerts() == [Alert("topic:/img", "topic_rate", 100.0, "error", "silent", {"silent_s": 1.5}),
                               Alert("node:/cam", "rosout", 101.0, "fatal", "boom", {})]
        assert [a.member for a in st.alerts(member="node:/cam")] == ["node:/cam"]
        assert [a.t for a in st.alerts(since=100.5)] == [101.0]
        s = st.series()
        assert set(s) == {"topic:/img", "node:/cam"}
        np.testing.assert_array_equal(s["topic:/img"], [100.0])
    mode = sqlite3.connect(path).execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"


def test_episodes_rate_limit_ongoing_symptom(tmp_path):
    with AlertStore(tmp_path / "e.sqlite", repeat_s=5.0, gap_s=3.0) as st:
        rows = []
        for t in range(0, 13):  # fires every second for 13 s
            sev = "error" if t == 7 else "warn"
            rows += st.add([Alert("topic:/img", "topic_rate", float(t), sev, "low")])
        rows += st.add([Alert("topic:/img", "topic_rate", 20.0, "warn", "low")])  # after a gap: new episode
        # 0 (new), 5 (repeat), 7 (escalation), 12 (5 s after 7), 20 (new episode)
        assert [a.t for a in rows] == [0.0, 5.0, 7.0, 12.0, 20.0]
        assert [a.t for a in st.alerts()] == [0.0, 5.0, 7.0, 12.0, 20.0]
        eps = st.episodes("topic:/img")
        assert [(e.start, e.end, e.count, e.max_severity) for e in eps] == [
            (0.0, 12.0, 13, "error"), (20.0, 20.0, 1, "warn")]
        # Another plugin on the same member is its own episode.
        st.add([Alert("topic:/img", "topic_latency", 1.0, "warn", "slow")])
        assert len(st.episodes()) == 3


def test_an_alert_may_hold_its_episode_open_through_a_pause(tmp_path):
    """A flapping symptom (silent 2 s, back 3 s, ...) with ``episode_hold_s`` is one episode; a
    pause longer than the hold, or an alert without one, still ends it."""
    def flap(t, hold=10.0):
        return Alert("topic:/img", "topic_rate", t, "error", "silent", {"episode_hold_s": hold})

    with AlertStore(tmp_path / "h.sqlite", repeat_s=5.0, gap_s=3.0) as st:
        rows = st.add([flap(t) for t in (0.0, 1.0, 5.0, 6.0, 10.0, 11.0, 15.0)])
        assert [a.t for a in rows] == [0.0, 5.0, 10.0, 15.0]  # one row per repeat_s, as before
        st.add([flap(26.0)])  # 11 s after the last one: longer than the hold
        st.add([flap(30.0, hold=0.0), flap(34.0)])  # the last alert had no hold: the 3 s gap rules
        st.add([Alert("node:/cam", "member_gone", 1.0, "warn", "x", {"episode_hold_s": "long"})])
        eps = [(e.start, e.end, e.count) for e in st.episodes("topic:/img")]
        assert eps == [(0.0, 15.0, 7), (26.0, 30.0, 2), (34.0, 34.0, 1)]
        assert len(st.episodes("node:/cam")) == 1  # a malformed hold is ignored, not an error


def test_snapshots_only_when_structure_changes(tmp_path):
    path = tmp_path / "s.sqlite"
    with AlertStore(path) as st:
        assert st.latest_snapshot() is None
        assert st.add_snapshot(1.0, _graph()) is True
        assert st.add_snapshot(2.0, _graph()) is False  # same members and edges
        assert st.add_snapshot(3.0, _graph(extra=True)) is True
        assert st.add_snapshot(4.0, _graph(extra=True), force=True) is True
    with AlertStore(path) as st:
        assert st.add_snapshot(5.0, _graph(extra=True)) is False  # remembered across reopening
        assert [t for t, _ in st.snapshots()] == [1.0, 3.0, 4.0]
        G = st.latest_snapshot(at=2.5)
        assert sorted(G.nodes) == ["node:/cam", "topic:/img"]
        assert G.nodes["node:/cam"]["pid"] == 10
        assert G.nodes["topic:/img"]["theta"][0] == 10.0
        assert sorted(st.latest_snapshot().nodes) == ["node:/cam", "node:/det", "topic:/img"]
        assert st.latest_snapshot(at=0.5) is None


def test_problems_and_unreadable(tmp_path):
    with AlertStore(tmp_path / "r.sqlite") as st:
        st.add_problems([PluginProblem("bad", "/x/bad.py", "run", "ValueError: no", "/x/bad.py:3 in check",
                                       t=11.0)])
        st.add_unreadable(11.5, {"process:42": "AccessDenied"})
        assert st.problems() == [
            {"t": 11.0, "plugin": "bad", "kind": "run", "where": "/x/bad.py", "message": "ValueError: no",
             "line": "/x/bad.py:3 in check", "count": 0},
            {"t": 11.5, "plugin": "", "kind": "unreadable", "where": "process:42", "message": "AccessDenied",
             "line": "", "count": 0}]


def test_a_monitor_tick_stores_what_changed(tmp_path):
    from stream_viz.model.diff import GraphDiff
    from stream_viz.records import Sample

    G, G2 = _graph(), _graph(extra=True)
    changed = GraphDiff(added_members=frozenset({"node:/det"}))
    problem = PluginProblem("bad", "/x/bad.py", "run", "ValueError: no")
    with AlertStore(tmp_path / "t.sqlite") as st:
        # The first tick keeps the model; later ones only when the sample's structure changed.
        alert, denied = Alert("node:/cam", "rosout", 1.0, "error", "boom"), {"process:42": "AccessDenied"}
        assert st.add_sample(Sample(1.0, G, unreadable=denied), G, [alert]) == [alert]
        assert st.add_sample(Sample(2.0, G, unreadable=denied), G, [], [problem]) == []  # same: once
        st.add_sample(Sample(3.0, G2, diff=changed, unreadable={"process:42": "gone"}), G2)
        st.add_sample(Sample(4.0, G2), G2)
        assert [t for t, _ in st.snapshots()] == [1.0, 3.0]
        assert [(p["t"], p["kind"], p["message"]) for p in st.problems()] == [
            (1.0, "unreadable", "AccessDenied"), (2.0, "run", "ValueError: no"), (3.0, "unreadable", "gone")]
        assert st.alerts() == [alert]


def test_a_second_run_is_refused_and_the_first_kept(tmp_path):
    path = tmp_path / "run.sqlite"
    with AlertStore(path) as st:
        st.begin_run(50.0)  # killed before it kept anything: taken over
    with AlertStore(path) as st:
        st.begin_run(100.0)
        st.add([Alert("node:/cam", "rosout", 101.0, "error", "boom")])
    refused = r"run\.sqlite: already holds a run .*1 alerts"
    with AlertStore(path) as st, pytest.raises(StoreError, match=refused):
        st.begin_run(200.0)
    with AlertStore(path, readonly=True) as st:
        assert st.get_meta("started_at") == 100.0
        assert [a.message for a in st.alerts()] == ["boom"]


def test_foreign_sqlite_file_is_refused(tmp_path):
    path = tmp_path / "foreign.sqlite"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE customers (id INTEGER)")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match=r"foreign\.sqlite.*another program"):
        AlertStore(path)
    # Untouched.
    assert sqlite3.connect(path).execute("SELECT name FROM sqlite_master").fetchall() == [("customers",)]


def test_foreign_file_with_user_version_is_refused(tmp_path):
    path = tmp_path / "v.sqlite"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE meta (key TEXT, value TEXT)")
    db.execute("PRAGMA user_version = 1")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match=r"v\.sqlite.*marker"):
        AlertStore(path)


def test_corrupt_file_is_refused(tmp_path):
    path = tmp_path / "junk.sqlite"
    path.write_bytes(np.random.default_rng(1).bytes(8192))
    with pytest.raises(StoreError, match=r"junk\.sqlite"):
        AlertStore(path)


def test_newer_schema_is_refused(tmp_path):
    path = tmp_path / "new.sqlite"
    AlertStore(path).close()
    db = sqlite3.connect(path)
    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match="newer"):
        AlertStore(path)


def test_migration_from_schema_1_keeps_alerts(tmp_path):
    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    for stmt in MIGRATIONS[0]:
        db.execute(stmt)
    db.execute("INSERT INTO meta VALUES ('app', ?)", (APP,))
    db.execute("INSERT INTO meta VALUES ('migrations', '[]')")
    db.execute("INSERT INTO alerts (member, plugin, t, severity, message, data) "
               "VALUES ('node:/a', 'rosout', 5.0, 'error', 'old', '{}')")
    db.execute("PRAGMA user_version = 1")
    db.commit()
    db.close()
    with pytest.raises(StoreError, match="needs migrating"):
        AlertStore(path, readonly=True)
    with AlertStore(path) as st:
        assert st.schema_version == SCHEMA_VERSION
        assert [m["to"] for m in st.get_meta("migrations")] == list(range(2, SCHEMA_VERSION + 1))
        assert st.alerts() == [Alert("node:/a", "rosout", 5.0, "error", "old", {})]
        st.add([Alert("node:/a", "rosout", 6.0, "error", "new")])
        assert len(st.episodes()) == 1
    with AlertStore(path, readonly=True) as st:
        assert len(st.alerts()) == 2


def test_readonly_missing_file(tmp_path):
    with pytest.raises(StoreError, match="no such"):
        AlertStore(tmp_path / "nope.sqlite", readonly=True)


def test_default_db_path_is_a_fresh_usable_file():
    path = default_db_path()
    try:
        assert path.exists() and path.stat().st_size == 0
        with AlertStore(path) as st:
            st.add([Alert("node:/a", "rosout", 1.0, "error", "x")])
        assert path != default_db_path()
    finally:
        path.unlink()


def test_sigkilled_writer_loses_nothing_committed(tmp_path):
    """A real child writes batches and is SIGKILLed mid-run; every batch it reported is there."""
    path = tmp_path / "k.sqlite"
    code = textwrap.dedent(f"""
        import sys, time
        from stream_viz.detect.store import AlertStore
        from stream_viz.records import Alert
        st = AlertStore({str(path)!r}, repeat_s=0.0)
        i = 0
        while True:
            st.add([Alert(f"node:/n{{j}}", "rosout", float(i), "error", "x") for j in range(3)])
            print(i, flush=True)
            i += 1
            time.sleep(0.005)
    """)
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    done = []
    try:
        while len(done) < 30:
            line = p.stdout.readline()
            assert line, "writer ended early"
            done.append(int(line))
        os.kill(p.pid, signal.SIGKILL)
        p.wait(10)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == -signal.SIGKILL
    assert (tmp_path / "k.sqlite-wal").exists()  # the WAL was not checkpointed by a clean close
    with AlertStore(path) as st:
        times = sorted({a.t for a in st.alerts()})
        # Every batch the child confirmed is stored whole (3 rows), maybe one more it had not printed.
        assert set(map(float, done)) <= set(times)
        assert len(times) in (len(done), len(done) + 1)
        assert all(len(st.alerts(since=t)) - len(st.alerts(since=t + 0.5)) == 3 for t in times)


def test_a_writer_killed_at_any_statement_of_the_schema_leaves_a_file_that_opens(tmp_path):
    """A real child creating the database is SIGKILLed as SQLite starts its k-th statement; the
    file then opens as an empty or a whole alert database, never as a half-made one."""
    n = 100  # more statements than the creation runs
    for k in range(n):
        path = tmp_path / f"k{k}.sqlite"
        code = textwrap.dedent(f"""
            import os, signal, sqlite3
            seen = []
            def trace(stmt):
                seen.append(stmt)
                if len(seen) > {k}:
                    os.kill(os.getpid(), signal.SIGKILL)
            connect = sqlite3.connect
            def traced(*a, **kw):
                db = connect(*a, **kw)
                db.set_trace_callback(trace)
                return db
            sqlite3.connect = traced
            from stream_viz.detect.store import AlertStore
            AlertStore({str(path)!r}).close()
        """)
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
        if p.returncode == 0:  # k past the last statement: the creation was whole
            break
        assert p.returncode == -signal.SIGKILL, p.stderr
        with AlertStore(path) as st:
            assert st.schema_version == SCHEMA_VERSION
            assert [m["to"] for m in st.get_meta("migrations")] == list(range(1, SCHEMA_VERSION + 1))
            st.add([Alert("node:/a", "rosout", 1.0, "error", "x")])
            assert len(st.alerts()) == 1
    else:
        pytest.fail(f"the creation ran over {n} statements")
    assert k > sum(len(m) for m in MIGRATIONS)  # the kills did land between the CREATEs
