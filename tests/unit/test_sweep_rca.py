"""The RCA sweep benchmark: which recordings it takes, and that the swept setting reaches the replay."""

from __future__ import annotations

import json
from pathlib import Path

from bench.sweep_rca import replay, suites

RESULTS = Path(__file__).resolve().parents[2] / "bench" / "results"


def test_suites_take_each_runs_newest_line_with_its_samples(tmp_path):
    s = tmp_path / "robot-abc" / "samples"
    s.mkdir(parents=True)
    lines = [{"fault": "crash_x", "truth": {"strict": "/old"}},
             {"fault": "crash_x", "truth": {"strict": "/x"}},
             {"fault": None}, {"fault": "hang_y"}]
    (s.parent / "runs.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    for name in ("crash_x", "healthy"):
        (s / f"{name}.jsonl.gz").write_bytes(b"")
    (tmp_path / "no-samples").mkdir()
    (tmp_path / "no-samples" / "runs.jsonl").write_text(json.dumps({"fault": "z"}) + "\n")
    [(name, runs, samples)] = suites(tmp_path)
    assert name == "robot-abc" and samples == s
    assert runs == {"crash_x": lines[1], "healthy": lines[2]}  # hang_y has no samples file


def test_the_swept_setting_reaches_the_replay():
    run = RESULTS / "manipulator-live-6b8bb75" / "samples" / "hang_mcu_sonar.jsonl.gz"
    assert len(replay(run, "top_k", "5")["root_causes"]) == 5
    assert len(replay(run, "top_k", "2")["root_causes"]) == 2
