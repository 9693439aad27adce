"""``--healthy RUN.sqlite``: a run starts from what an earlier healthy run learned (real CLI,
real databases; the effect on a recorded robot is `tests/unit/test_replay_recorded.py`)."""

from __future__ import annotations

import json
import os

import pytest

from stream_viz.detect.store import AlertStore
from stream_viz.testing import TALKER
from tests.cli.test_cli import check_report, run_cli


def test_a_monitor_saves_what_it_learned_and_the_next_starts_from_it(children, tmp_path):
    children.python(TALKER, name="talker")
    first, second = tmp_path / "first.sqlite", tmp_path / "second.sqlite"
    out = run_cli(["monitor", "--duration", "6", "--viewer", "none", "--db", str(first)], children.env)
    assert out.returncode == 0, out.stderr
    assert f"start the next from it: --healthy {first}" in out.stderr  # the user is told how
    out = run_cli(["monitor", "--duration", "4", "--viewer", "none", "--db", str(second),
                   "--healthy", str(first), "--report", str(tmp_path / "r.json")], children.env)
    assert out.returncode == 0, out.stderr
    assert f"starting from what the healthy run {first} showed" in out.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    check_report(report)
    assert report["healthy_from"] == str(first)
    for path in (first, second):
        store = AlertStore(path, readonly=True)
        try:
            assert isinstance(store.get_meta("learned"), dict)
            assert store.get_meta("healthy_from") == (str(first) if path == second else None)
        finally:
            store.close()


def _killed(path):
    store = AlertStore(path)
    store.begin_run(100.0)  # and never closed by a monitor: no `learned`
    store.close()


@pytest.mark.parametrize(("make", "message"), [
    (None, "missing.sqlite: no such alert database"),
    (_killed, "killed.sqlite: holds nothing learned to start from: its run did not end (killed?)"),
    (lambda p: p.write_text("not a database"), "text.sqlite: not a readable stream-viz alert database"),
])
def test_a_healthy_run_that_cannot_be_read_is_one_error_line_before_anything_starts(tmp_path, make, message):
    from tests.unit.test_samples_file import _gone_run, write_file

    samples = write_file(tmp_path / "s.jsonl.gz", _gone_run())
    healthy = tmp_path / message.split(":")[0]
    if make is not None:
        make(healthy)
    db = tmp_path / "new.sqlite"
    out = run_cli(["replay", str(samples), "--db", str(db), "--healthy", str(healthy)], dict(os.environ),
                  timeout=60)
    assert out.returncode == 2, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.startswith("Error: ")]
    assert len(lines) == 1 and message in lines[0] and str(healthy) in lines[0], out.stderr
    assert "Traceback" not in out.stderr
    assert not db.exists()  # refused before the run's database was made


def test_monitor_refuses_a_missing_healthy_run_before_it_attaches(tmp_path):
    out = run_cli(["monitor", "--duration", "1", "--db", str(tmp_path / "n.sqlite"),
                   "--healthy", str(tmp_path / "nope.sqlite")], dict(os.environ), timeout=60)
    assert out.returncode == 2 and "nope.sqlite: no such alert database" in out.stderr, out.stderr
