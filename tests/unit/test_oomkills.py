"""Which ended processes the OOM killer ended: the attribution on literal counts, the watch on a
literal cgroup tree."""

from __future__ import annotations

from pathlib import Path

from stream_viz.collect.cgroups import Mount
from stream_viz.collect.oomkills import OomKill, OomWatch, attribute


def test_a_risen_count_names_the_largest_ended_processes_of_its_group():
    exited = {10: ("/a", 300.0), 11: ("/a", 900.0), 12: ("/b", 50.0), 13: ("/a", 20.0)}
    assert attribute({"/a": 1}, exited) == {11: "/a"}  # the OOM killer picks by memory
    assert attribute({"/a": 2, "/b": 1}, exited) == {11: "/a", 10: "/a", 12: "/b"}
    assert attribute({"/c": 1}, exited) == {}  # a kill in a group where nothing we follow ended
    assert attribute({}, exited) == {}


def _tree(root: Path, count: int) -> list[Mount]:
    for pid in (7, 8):
        (root / f"proc/{pid}").mkdir(parents=True, exist_ok=True)
        (root / f"proc/{pid}/cgroup").write_text("4:memory:/robot\n")
    (root / "mem/robot").mkdir(parents=True, exist_ok=True)
    (root / "mem/robot/memory.limit_in_bytes").write_text(f"{64 * 2**20}\n")
    (root / "mem/robot/memory.oom_control").write_text(f"oom_kill_disable 0\nunder_oom 0\noom_kill {count}\n")
    return [Mount(str(root / "mem"), "/", frozenset({"memory"}))]


def _watch(tmp_path: Path, monkeypatch) -> OomWatch:
    """A watch over the literal tree of `_tree` (its /proc under ``tmp_path``), no kill counted."""
    import stream_viz.collect.oomkills as oomkills
    real = oomkills.memory_group_of
    monkeypatch.setattr(oomkills, "memory_group_of", lambda pid, m: real(pid, m, proc=str(tmp_path / "proc")))
    return OomWatch(_tree(tmp_path, 0))


def test_the_watch_names_a_process_that_ended_as_its_group_counted_a_kill(tmp_path, monkeypatch):
    w = _watch(tmp_path, monkeypatch)
    assert w.update([7, 8], {}) == {}
    # 8 ends while the count is unchanged: not the OOM killer (a crash, a kill by someone).
    assert w.update([7], {8: 500.0}) == {}
    _tree(tmp_path, 1)
    killed = w.update([], {7: 700.0})
    assert killed == {7: OomKill(str(tmp_path / "mem/robot"), 64 * 2**20)}
    assert "OOM killer at its group's limit of 64 MB" in killed[7].describe()


def test_a_kill_counted_a_sample_before_its_process_is_seen_gone_names_it(tmp_path, monkeypatch):
    # The processes are read before the counts: one killed in between is counted first.
    w = _watch(tmp_path, monkeypatch)
    assert w.update([7, 8], {}) == {}
    _tree(tmp_path, 1)
    assert w.update([7, 8], {}) == {}
    assert set(w.update([8], {7: 100.0})) == {7}
    # A count that named nobody within a sample is dropped: a later end is no OOM kill.
    _tree(tmp_path, 2)
    assert w.update([8], {}) == {}
    assert w.update([8], {}) == {}
    assert w.update([], {8: 100.0}) == {}
