"""The evaluation's suites (which runs), the size sweep's tables and the committed result files."""

from __future__ import annotations

import json
from collections import Counter

import pytest

from bench.eval.publish import KEEP, publish
from bench.eval.results import results_md
from bench.eval.score import floor_rows, latencies, sweep_rows
from bench.eval.suites import AMR_FULL, CONTROL_S, SWEEP, plan, run_id, timeout
from bench.eval.systems import fault_reach, system_topology
from stream_viz.demo.amr.topology import AMR, DEFAULT_TARGETS
from stream_viz.demo.faults import FaultSpec


def test_short_runs_every_amr_fault_on_its_default_target_beside_the_demo():
    specs = plan("short")
    amr = [s for s in specs if s["system"] == "amr"]
    assert {s["fault"]: s["target"] for s in amr if s["fault"]} == DEFAULT_TARGETS
    assert Counter(s["system"] for s in specs) == {"demo": 9, "amr": 13, "gen20": 1}
    assert sum(1 for s in amr if s["fault"] is None) == 1
    # the AMR injects later: its one-shot job ends 25 s after start, in the healthy part of the run
    assert {(s["system"], s["warmup"], s["post"]) for s in specs} == {
        ("demo", 20.0, 25.0), ("gen20", 20.0, 25.0), ("amr", 25.0, 20.0)}
    assert {(s["warmup"], s["post"]) for s in plan("short", warmup=30.0, post=10.0)} == {(30.0, 10.0)}


def test_full_runs_each_amr_fault_on_two_or_three_targets_and_the_control_run():
    specs = plan("full", sizes=[20], reps=2)
    amr = [s for s in specs if s["system"] == "amr" and s["fault"]]
    per_kind = Counter(s["fault"] for s in amr if s["rep"] == 0)
    assert per_kind == {f: len(ts) for f, ts in AMR_FULL.items()}
    assert all(2 <= n <= 3 for f, n in per_kind.items() if f != "slow_service")  # one server with work
    assert len(amr) == 2 * sum(per_kind.values())
    for s in amr:
        AMR.check_fault(FaultSpec(s["fault"], s["target"]))
    (control,) = [s for s in specs if s.get("control")]
    assert control == plan("control")[0]
    assert control["fault"] is None and control["warmup"] + control["post"] == CONTROL_S == 600
    assert len({run_id(s) for s in specs}) == len(specs)


def test_the_sweep_runs_each_sized_kind_at_several_sizes_once():
    specs = plan("sweep")
    assert {s["fault"] for s in specs} == {"degrade", "leak", "delay", "cpu", "errlog"}
    assert len(specs) == sum(len(sizes) for _, _, sizes in SWEEP)
    for s in specs:
        AMR.check_fault(FaultSpec(s["fault"], s["target"], size=s["size"]))
    assert {s["target"] for s in specs if s["fault"] == "delay"} == {"/amr1/front_lidar",
                                                                      "/amr1/diagnostic_aggregator"}
    assert len(plan("sweep", reps=2)) == 2 * len(specs)
    with pytest.raises(ValueError, match="short, full, control or sweep"):
        plan("huge")


def test_run_ids_name_the_size_and_the_control_run():
    assert run_id({"system": "amr", "fault": "degrade", "target": "/amr1/front_lidar", "size": 0.7}) == \
        "amr_degrade_amr1.front_lidar_s0.7_0"
    assert run_id({"system": "demo", "fault": "crash", "target": "/lidar_driver", "rep": 1}) == \
        "demo_crash_lidar_driver_1"
    assert run_id(plan("control")[0]) == "amr_control_600s_0"
    assert timeout({"warmup": 600.0, "post": 0.0}) > 600 + 120  # the control run is not cut short


def test_a_faults_reach_is_its_process_downstream_and_a_servers_clients():
    reach = fault_reach(system_topology("amr"), "/amr1/planner_server", {"process:5": "navigation",
                                                                       "process:6": "behavior"})
    assert {"node:/amr1/amcl", "process:5", "node:/amr1/bt_navigator", "topic:/amr1/plan"} <= reach
    assert "process:6" not in reach and "topic:/amr1/pallet_detections" not in reach
    demo = fault_reach(system_topology("demo"), "node:/lidar_driver", {})
    assert demo >= {"node:/lidar_driver", "topic:/scan", "node:/obstacle_detector", "topic:/cmd_vel"}
    assert "node:/camera_driver" not in demo


def _sized(size, detected_at, top, before=0, rep=0):
    """A recorded degrade run of ``size``: alerts on the target at ``detected_at`` (s after 100)."""
    alerts = [{"t": 90.0, "member": "node:/z", "plugin": "p"}] * before
    if detected_at is not None:
        alerts.append({"t": 100.0 + detected_at, "member": "topic:/y", "plugin": "topic_rate"})
    alerts += [{"t": 101.0, "member": "node:/z", "plugin": "p"}]  # out of the fault's reach
    return {
        "spec": {"system": "amr", "fault": "degrade", "target": "/b", "size": size, "rep": rep},
        "rankings": {"live": top, "baseline": []},
        "expand": {"node:/a": ["node:/a"], "node:/b": ["node:/b"], "node:/c": ["node:/c"],
                   "process:7": ["node:/b", "node:/c"]},
        "truth_strict": ["node:/b"], "truth_process": ["node:/b", "node:/c"],
        "reach": ["node:/b", "topic:/y"], "injected": {"t": 100.0}, "alerts": alerts, "ticks": [],
    }


def test_the_sweep_tables_find_the_weakest_size_detected_and_ranked_first():
    runs = [
        _sized(0.25, 2.0, ["node:/b"]),
        _sized(0.9, None, ["node:/a"]),  # only the out-of-reach alert: not detected
        _sized(0.7, 4.0, ["node:/a", ["node:/b", "node:/c"]], before=2),
        _sized(0.5, 3.0, ["process:7"]),
    ]
    assert latencies(runs[1])["detected"] is None and latencies(runs[1])["first_alert"] == 1.0
    rows = sweep_rows(runs)
    assert [r["size"] for r in rows] == [0.9, 0.7, 0.5, 0.25]  # degrade: a larger fraction is weaker
    r07 = rows[1]
    assert (r07["detected"], r07["rank_strict"], r07["rank_process"]) == (4.0, 2.5, 2.0)
    assert r07["alerts_before"] == 2 and r07["AC@1_process"] == 0.0
    assert rows[2]["AC@1_process"] == 1.0 and rows[2]["rank_strict"] == 1.5
    (floor,) = floor_rows(rows)
    assert floor == {"system": "amr", "fault": "degrade", "target": "/b", "sizes": [0.9, 0.7, 0.5, 0.25],
                     "weakest_detected": 0.7, "detected_s": 4.0, "rank_strict": 2.5, "rank_process": 2.0,
                     "weakest_first": 0.5}
    # a size counts only if every repetition qualifies
    (floor,) = floor_rows(sweep_rows([*runs, _sized(0.7, None, ["node:/a"], rep=1)]))
    assert floor["weakest_detected"] == 0.5 and floor["detected_s"] == 3.0
    text = results_md([(r | {"loadavg": [1.0], "wall_s": 45.0, "cpu_share": 0.02, "peak_rss_mb": 90.0,
                             "samples": 45, "baseline_flags": {}}, None) for r in runs], [])
    assert "| amr | degrade | /b | 0.9, 0.7, 0.5, 0.25 | 0.7 | 4.0 | 2.5 / 2.0 | 0.5 |" in text.splitlines()


def test_the_control_run_lists_every_alert(tmp_path):
    run = {"spec": plan("control")[0], "t_ready": 1000.0, "wall_s": 600.0, "loadavg": [1.0],
           "cpu_share": 0.02, "peak_rss_mb": 90.0, "samples": 600, "baseline_flags": {},
           "alerts": [{"t": 1250.0, "member": "topic:/amr1/dock_pose", "plugin": "topic_rate",
                       "severity": "warn", "message": "silent for 5.0 s | was 1 Hz"}]}
    lines = results_md([(run, None)], []).splitlines()
    assert "### Healthy-dynamics control run amr_control_600s_0: 1 alerts in 600 s (0 is the goal)" in lines
    assert "| 250 | topic:/amr1/dock_pose | topic_rate | warn | silent for 5.0 s / was 1 Hz |" in lines


def test_publish_writes_small_files_that_say_what_ran_on_what(tmp_path):
    out, root = tmp_path / "out", tmp_path / "results"
    out.mkdir()
    code = {"commit": "0123456789abcdef", "dirty": False}
    machine = {"cores": 2, "cpu": "AMD EPYC"}
    runs = [{"spec": {"system": "amr"}, "code": code, "machine": machine, "t_start": 0.0, "loadavg": [0.5],
             "rankings": {"live": [f"node:/n{i}" for i in range(30)], "_cost_ms": {"x": 1.0}},
             "peers": {"BARO": {"ranking": list("abcdefghijklmnop"), "columns": ["c"], "seconds": 1.0},
                       "HT": {"error": "boom", "trace": "..."}},
             "alerts": [{"t": 1.0, "member": "m", "plugin": "p", "message": "x" * 500}]},
            {"spec": {"system": "amr"}, "code": {**code, "dirty": True}, "machine": machine, "t_start": 60.0,
             "loadavg": [1.5], "rankings": {}, "peers": None, "alerts": []}]
    (out / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs))
    (out / "summary.json").write_text(json.dumps({"rows": [1, 2], "latency": [], "cost": []}))
    (out / "results.md").write_text("tables\n")
    (out / "scores.csv").write_text("a,b\n1,2\n")
    dest = publish(out, "short", root, ["--short"])
    assert dest == root / "short-0123456-dirty"
    assert sorted(p.name for p in dest.iterdir()) == ["about.json", "results.md", "runs.jsonl", "scores.csv",
                                                       "summary.json"]
    assert json.loads((dest / "summary.json").read_text()) == {"latency": [], "cost": []}
    first = json.loads((dest / "runs.jsonl").read_text().splitlines()[0])
    assert len(first["rankings"]["live"]) == KEEP and first["rankings"]["_cost_ms"] == {"x": 1.0}
    assert first["peers"] == {"BARO": {"ranking": list("abcdefghij"), "seconds": 1.0},
                              "HT": {"error": "boom"}}
    assert len(first["alerts"][0]["message"]) == 120
    about = json.loads((dest / "about.json").read_text())
    assert about["command"] == "python -m bench.eval.run --short"
    assert about["commits"] == {"0123456789abcdef": 2}
    assert about["dirty"] == ["0123456789abcdef"] and about["machines"] == [machine]
    assert about["load_1min"] == [0.5, 1.5] and about["first_run"] == "1970-01-01T00:00Z"
