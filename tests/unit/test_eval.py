"""The evaluation's pure parts: AC@k/Avg@5 with ties, the rate-monitor baseline, the metric table."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from bench.eval.baseline import culprits, flag_times
from bench.eval.export import column_graph, service_name, wide_table
from bench.eval.metrics import aggregate, expected_rank, hit_at, scores, tie_blocks, to_blocks
from bench.eval.score import accuracy_table, fault_matrix, latencies, score_run

EXPAND = {
    "node:/a": ["node:/a"],
    "node:/b": ["node:/b"],
    "node:/c": ["node:/c"],
    "topic:/x": ["node:/a"],
    "process:7": ["node:/b", "node:/c"],
}


def test_blocks_map_topics_and_processes_and_skip_repeats_and_unknowns():
    assert to_blocks(["topic:/x", "root", "node:/a", "process:7", "node:/c"], EXPAND) == [
        ("node:/a",),
        ("node:/b", "node:/c"),
    ]
    assert to_blocks([("node:/c", "topic:/x")], EXPAND) == [("node:/c", "node:/a")]


def test_hit_at_is_exact_under_random_tie_breaking():
    blocks = [("node:/a",), ("node:/b", "node:/c")]
    assert hit_at(blocks, {"node:/a"}, 1) == 1.0
    assert hit_at(blocks, {"node:/b"}, 1) == 0.0
    assert hit_at(blocks, {"node:/b"}, 2) == pytest.approx(0.5)
    assert hit_at(blocks, {"node:/b"}, 3) == 1.0
    assert hit_at(blocks, {"node:/b", "node:/c"}, 2) == 1.0  # process-level truth: either counts
    assert hit_at(blocks, {"node:/z"}, 5) == 0.0
    # three tied, one true, two slots left: 1 - C(2,2)/C(3,2) = 2/3
    assert hit_at([("a",), ("b", "c", "d")], {"c"}, 3) == pytest.approx(2 / 3)


def test_expected_rank_and_scores():
    blocks = [("node:/a",), ("node:/b", "node:/c")]
    assert expected_rank(blocks, {"node:/c"}) == pytest.approx(2.5)
    assert expected_rank(blocks, {"node:/q"}) is None
    s = scores(blocks, {"node:/b"})
    assert s["AC@1"] == 0.0 and s["AC@3"] == 1.0
    assert s["Avg@5"] == pytest.approx((0 + 0.5 + 1 + 1 + 1) / 5)
    agg = aggregate([{"AC@1": 1.0, "AC@3": 1.0, "Avg@5": 1.0}, {"AC@1": 0.0, "AC@3": 1.0, "Avg@5": 0.6}])
    assert agg == {"AC@1": 0.5, "AC@3": 1.0, "Avg@5": 0.8, "n": 2}


def test_equal_scores_form_tied_blocks():
    scored = [("node:/a", 0.9), ("node:/b", 0.5), ("node:/c", 0.5), ("process:7", 0.5), ("node:/d", 0.1)]
    assert tie_blocks(scored) == ["node:/a", ("node:/b", "node:/c", "process:7"), "node:/d"]
    assert tie_blocks([("x", 1.0), ("y", 1.0)]) == [("x", "y")]
    assert tie_blocks([]) == []


def test_our_tied_ranking_scores_expected_ac_at_k_like_a_peers():
    run = _run("hang")
    run["expand"] = {**EXPAND, "node:/d": ["node:/d"]}
    # as run.json stores it: a tie is a JSON list; /b, /c and /d scored equal, behind /a
    run["rankings"] = {"live": ["node:/a", ["node:/c", "node:/b", "node:/d"]], "baseline": []}
    by = {r["level"]: r for r in score_run(run, None) if r["method"] == "stream-viz (live)"}
    strict = by["strict"]  # /b: one of three tied at ranks 2-4
    assert [strict[f"AC@{k}"] for k in (1, 2, 3, 4, 5)] == pytest.approx([0, 1 / 3, 2 / 3, 1, 1])
    assert strict["rank"] == pytest.approx(3.0) and strict["Avg@5"] == pytest.approx(3 / 5)
    process = by["process"]  # /b or /c: two of the three
    assert [process[f"AC@{k}"] for k in (1, 2, 3)] == pytest.approx([0, 2 / 3, 1])
    assert process["rank"] == pytest.approx(2 + 1 / 3)
    run["ticks"] = [{"t": 101.0, "top": [["node:/b", "node:/c"]]}, {"t": 103.0, "top": ["node:/b"]}]
    la = latencies(run)  # a tie is first only at the level where every tied node is true
    assert la["top1_process"] == 1.0 and la["top1_strict"] == 3.0


def test_baseline_flags_silent_and_slow_topics_not_healthy_or_never_alive():
    t = np.arange(10.0)
    rates = {
        "topic:/healthy": (t, np.full(10, 10.0)),
        "topic:/slow": (t, np.array([10.0] * 6 + [4.0] * 4)),  # below half the median at t=6
        "topic:/silent": (t, np.array([5.0] * 8 + [0.0] * 2)),  # zero at t=8
        "topic:/never": (t, np.zeros(10)),  # never alive: not "silent"
        "topic:/rosout": (t, np.array([1.0] * 5 + [0.0] * 5)),  # ignored (event-driven)
        "topic:/gone": (t[:7], np.full(7, 3.0)),  # vanished before the end
    }
    flags = flag_times(rates, end=9.0)
    assert flags == {"topic:/slow": 6.0, "topic:/silent": 8.0, "topic:/gone": 7.0}
    pubs = {"topic:/slow": ["node:/a"], "topic:/silent": ["node:/b"], "topic:/gone": ["node:/c", "node:/a"]}
    assert culprits(flags, pubs) == [("node:/a",), ("node:/c", "node:/a"), ("node:/b",)]
    assert culprits({"topic:/slow": 1.0, "topic:/silent": 1.0}, pubs) == [
        ("node:/b", "node:/a")
    ]  # same sample: tied


def test_wide_table_aligns_fills_and_names_with_one_underscore():
    from stream_viz.model.theta import SCHEMAS, make_theta

    def topic(rate):
        return make_theta("topic", {"rate_hz": rate, "jitter_ms": 1.0})

    series = {
        "topic:/cam_raw": (np.array([1.0, 2.0, 3.0]), np.vstack([topic(10), topic(float("nan")), topic(8)])),
        "process:42": (np.array([2.0]), make_theta("process", {"cpu_percent": 50.0})[None, :]),
        "topic:/rosout": (np.array([1.0]), topic(1)[None, :]),
    }
    times, cols, m, services = wide_table(series, SCHEMAS, {"process:42": "base_group"})
    assert list(times) == [1.0, 2.0, 3.0]
    assert "topic.cam-raw_rate" in cols and "proc.base-group_cpu" in cols
    assert all(c.count("_") == 1 for c in cols)
    assert not any(c.startswith("topic.rosout") for c in cols)
    assert services == {"topic.cam-raw": "topic:/cam_raw", "proc.base-group": "process:42"}
    rate = m[:, cols.index("topic.cam-raw_rate")]
    assert list(rate) == [10.0, 10.0, 8.0]  # NaN carries forward
    cpu = m[:, cols.index("proc.base-group_cpu")]
    assert list(cpu) == [50.0, 50.0, 0.0]  # first value before, 0 after it vanished
    assert service_name("node:/ns/my_node") == "node.ns.my-node"


def test_the_processes_of_a_respawned_group_are_one_series():
    from stream_viz.model.theta import SCHEMAS, make_theta

    def proc(cpu):
        return make_theta("process", {"cpu_percent": cpu})

    series = {"process:11": (np.array([1.0, 2.0]), np.vstack([proc(10), proc(20)])),
              "process:12": (np.array([4.0, 5.0]), np.vstack([proc(30), proc(40)]))}
    times, cols, m, services = wide_table(series, SCHEMAS, {"process:11": "camera", "process:12": "camera"})
    assert cols.count("proc.camera_cpu") == 1 and services == {"proc.camera": "process:11"}
    assert list(times) == [1.0, 2.0, 4.0, 5.0]
    assert list(m[:, cols.index("proc.camera_cpu")]) == [10.0, 20.0, 30.0, 40.0]


def test_column_graph_links_metrics_and_drops_cycles():
    cols = ["a_x", "a_y", "b_x", "c_x"]
    parents = column_graph(cols, [("a", "b"), ("b", "c"), ("c", "a"), ("zz", "a")])
    assert parents == {"a_x": [], "a_y": [], "b_x": ["a_x", "a_y"], "c_x": ["b_x"]}


def _run(fault="crash"):
    return {
        "spec": {"system": "demo", "fault": fault, "target": "/b"},
        "rankings": {"live": ["node:/b"], "both/trajectory": ["process:7"], "baseline": [["node:/a"]]},
        "expand": EXPAND,
        "truth_strict": ["node:/b"],
        "truth_process": ["node:/b", "node:/c"],
        "reach": ["node:/b", "node:/c", "process:7", "topic:/y"],
        "injected": {"t": 100.0},
        "alerts": [{"t": 101.0, "member": "node:/b"}],
        "baseline_first_flag_s": None,
        "ticks": [
            {"t": 99.0, "top": ["node:/b"]},
            {"t": 101.0, "top": ["process:7"]},
            {"t": 102.0, "top": ["node:/b"]},
        ],
    }


def test_score_run_latencies_and_tables():
    rows = score_run(_run(), {"BARO": {"ranking": ["node:/c", "node:/b"]}, "HT": {"error": "boom"}})
    by = {(r["method"], r["level"]): r for r in rows}
    assert by[("stream-viz (live)", "strict")]["AC@1"] == 1.0
    assert by[("ours both/trajectory", "strict")]["AC@1"] == 0.5
    assert by[("ours both/trajectory", "process")]["AC@1"] == 1.0
    assert by[("rate monitor + first alert", "strict")]["AC@5"] == 0.0
    assert by[("BARO", "strict")]["AC@1"] == 0.0 and by[("BARO", "process")]["AC@1"] == 1.0
    assert not any(r["method"] == "HT" for r in rows)
    # a crash is injected into the whole process: judged there; a hang into the node: judged there
    assert by[("ours both/trajectory", "injected")]["AC@1"] == 1.0
    hang = {(r["method"], r["level"]): r for r in score_run(_run("hang"), None)}
    assert hang[("ours both/trajectory", "injected")]["AC@1"] == 0.5
    assert score_run(_run(None), None) == []
    la = latencies(_run())
    assert la["top1_strict"] == 2.0 and la["top1_process"] == 1.0 and la["baseline_first_flag"] is None
    table = accuracy_table(rows, ["stream-viz (live)", "BARO"])
    assert "| stream-viz (live) | 1 | 1.00 |" in table
    assert table.splitlines()[0].endswith("| AC@1 inj | AC@3 inj |")
    assert "| BARO | 0.00 | 0.00 |" in fault_matrix(rows, ["BARO"])


def test_an_alert_stamped_within_a_sample_of_the_injection_counts_as_after():
    run = _run()
    run["alerts"] = [{"t": 99.96, "member": "node:/b"}, {"t": 50.0, "member": "node:/a"}]
    from bench.eval.score import alerts_before

    assert [a["t"] for a in alerts_before(run)] == [50.0]
    assert latencies(run)["first_alert"] == 0.0


def test_report_writes_the_results_page_and_the_data_behind_it(tmp_path):
    from bench.eval.run import report, run_id

    def recorded(run, cpu, flags):
        return {**run, "loadavg": [0.5, 0.4, 0.3], "wall_s": 40.2, "cpu_share": cpu, "peak_rss_mb": 100.0,
                "samples": 40, "nodes": 12, "baseline_flags": flags}

    faulty = recorded(_run(), 0.02, {})
    clean = recorded(_run(None), 0.04, {"topic:/x": 5.0})
    clean["alerts"] = [{"t": 5.0, "member": "node:/a", "plugin": "topic_rate"}]
    for run in (faulty, clean):
        (tmp_path / run_id(run["spec"])).mkdir()
        (tmp_path / run_id(run["spec"]) / "run.json").write_text(json.dumps(run))
    (tmp_path / run_id(faulty["spec"]) / "peers.json").write_text(json.dumps({"HT": {"error": "boom"}}))

    text = report(tmp_path)
    assert (tmp_path / "results.md").read_text() == text
    lines = text.splitlines()
    assert lines[0].startswith("Runs: 1 with a fault, 1 fault-free; load average (1 min) during runs 0.5–0.5")
    # first alert, first alert on a member the fault reaches, top-1 per level, the rate monitor
    assert "| demo | crash | /b | 1.0 | 1.0 | 2.0 | 1.0 | 1.0 | – |" in lines
    assert "| demo_nofault_b_0 | demo | 40 | 1 | node:/a (topic_rate) | 1 |" in lines
    assert "Faulty runs with alerts before the injection: 0 of 1" in lines
    assert "| demo | 2 | 3.0 % / 4.0 % | 100 | 40 |" in lines  # CPU mean / max, RSS, samples per run
    assert lines[-1] == "Peers that failed on some run: HT: boom"

    rows = score_run(faulty, {"HT": {"error": "boom"}})
    with open(tmp_path / "scores.csv") as f:
        written = list(csv.DictReader(f))
    assert written == [{k: "" if v is None else str(v) for k, v in r.items()} for r in rows]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["rows"] == rows
    assert summary["latency"] == [{"system": "demo", "fault": "crash", "size": None, **latencies(faulty)}]
    assert [c["cpu_share"] for c in summary["cost"]] == [0.02, 0.04]
    lines = [json.loads(x) for x in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert [x["latency"] is None for x in lines] == [False, True]
    assert not any("ticks" in x or "expand" in x for x in lines)
