"""The evaluation's suites as data: which runs each one makes (``short``, ``full``, ``control``, ``sweep``).

A run is a spec (a dict): ``system``, ``fault`` (None: fault-free), ``target``, optionally ``size``
(`FaultSpec.size`), ``warmup`` (s from ready to the injection; fault-free runs monitor ``warmup``
+ ``post`` as well), ``post`` (s monitored after it),
``rep``, ``seed`` (generated systems), ``control`` (the long healthy run). `run_id` names its folder.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from stream_viz.demo.amr.topology import DEFAULT_TARGETS as AMR_DEFAULT
from stream_viz.demo.faults import BASIC_FAULTS

DEMO_SHORT = {
    "crash": "/lidar_driver",
    "hang": "/localization",
    "degrade": "/lidar_driver",
    "cpu": "/global_planner",
    "leak": "/map_server",
    "delay": "/obstacle_detector",
    "errlog": "/controller",
    "diag": "/wheel_odometry",
}
DEMO_FULL = {
    "crash": ("/lidar_driver", "/localization", "/map_server"),
    "hang": ("/localization", "/lidar_driver", "/global_planner"),
    "degrade": ("/lidar_driver", "/imu_driver", "/camera_driver"),
    "cpu": ("/global_planner", "/camera_driver", "/localization"),
    "leak": ("/map_server", "/obstacle_detector", "/controller"),
    "delay": ("/obstacle_detector", "/wheel_odometry", "/local_planner"),
    "errlog": ("/controller", "/lidar_driver", "/battery_monitor"),
    "diag": ("/wheel_odometry", "/map_server", "/local_planner"),
}


def _amr(*names: str) -> tuple[str, ...]:
    return tuple(f"/amr1/{n}" for n in names)


# The AMR's fault kinds, each on its default target first, then on others in other kinds of
# process (single- / multi-threaded container, a process per node, a respawned one).
AMR_FULL: dict[str, tuple[str, ...]] = {
    "crash": _amr("amcl", "pallet_detector", "bt_navigator"),
    "hang": _amr("scan_merger", "local_costmap", "image_rectifier"),
    "degrade": _amr("front_lidar", "imu_driver", "camera_driver"),
    "cpu": _amr("pallet_detector", "local_costmap", "base_driver"),
    "leak": _amr("local_costmap", "scan_merger", "diagnostic_aggregator"),
    "delay": _amr("base_driver", "front_lidar", "camera_driver"),
    "errlog": _amr("controller_server", "amcl", "zone_manager"),
    "diag": _amr("base_driver", "front_lidar", "imu_driver"),
    "slow_service": _amr("planner_server"),  # the robot's only server with work per call
    "qos": _amr("amcl", "local_costmap", "scan_merger"),
    "restart": _amr("camera_driver", "base_driver"),  # the respawned processes
    "flap": _amr("rear_lidar", "imu_driver", "camera_driver"),
}
assert all(AMR_FULL[f][0] == t for f, t in AMR_DEFAULT.items()) and set(AMR_FULL) == set(AMR_DEFAULT)

CONTROL_S = 600.0  # the AMR's healthy-dynamics control run

# Fault sizes (`FaultSpec.size`), weakest first, per kind and target, on the AMR: the 10 Hz front
# scan (stamped; the merged scan keeps its stamp) and the 1 Hz diagnostic aggregator's outputs.
SWEEP: tuple[tuple[str, str, tuple[float, ...]], ...] = (
    ("degrade", "/amr1/front_lidar", (0.7, 0.5, 0.25)),  # fraction of messages kept
    ("degrade", "/amr1/diagnostic_aggregator", (0.7, 0.25)),
    ("delay", "/amr1/front_lidar", (20.0, 50.0, 100.0, 400.0)),  # ms
    ("delay", "/amr1/diagnostic_aggregator", (50.0, 400.0)),
    ("leak", "/amr1/local_costmap", (1.0, 2.0, 5.0, 20.0)),  # MB/s
    ("cpu", "/amr1/pallet_detector", (0.1, 0.25, 0.5, 1.0)),  # share of a core
    ("errlog", "/amr1/controller_server", (0.2, 0.5, 2.0)),  # lines/s
)


# Seconds from ready to the injection, and monitored after it. The AMR waits 5 s longer so that
# its one-shot job's exit (25 s after start) falls in the healthy part, before the injection.
TIMING: dict[str, tuple[float, float]] = {"amr": (25.0, 20.0)}
DEFAULT_TIMING = (20.0, 25.0)
# A fault fires half a sample period after its warm-up: the monitor samples on the warm-up's
# whole seconds, and a fault firing on a sample's start was seen by a sample stamped before it.
INJECT_PHASE = 0.5


def plan(suite: str, warmup: float | None = None, post: float | None = None, sizes: Sequence[int] = (),
         reps: int = 1) -> list[dict]:
    """The run specs of ``suite``: ``short``, ``full``, ``control`` or ``sweep``.

    ``warmup`` and ``post`` (s) override every system's own `TIMING` (not the control run's).
    """
    specs = _runs(suite, sizes, reps)
    for spec in specs:
        if not spec.get("control"):
            w, p = TIMING.get(spec["system"], DEFAULT_TIMING)
            spec["warmup"], spec["post"] = (w if warmup is None else warmup), (p if post is None else post)
    return specs


def _runs(suite: str, sizes: Sequence[int], reps: int) -> list[dict]:
    if suite == "short":
        return [*_demo_short(), *_amr_runs(AMR_DEFAULT.items(), 0)]
    if suite == "control":
        return [control()]
    if suite == "sweep":
        return [
            {"system": "amr", "fault": f, "target": t, "size": s, "rep": r}
            for r in range(reps)
            for f, t, sizes_ in SWEEP
            for s in sizes_
        ]
    if suite != "full":
        raise ValueError(f"unknown suite {suite!r}: short, full, control or sweep")
    runs: list[dict] = []
    for r in range(reps):
        runs += [{"system": "demo", "fault": f, "target": t, "rep": r}
                 for f in BASIC_FAULTS for t in DEMO_FULL[f]]
        runs.append({"system": "demo", "fault": None, "target": None, "rep": r})
        runs += _amr_runs(((f, t) for f, ts in AMR_FULL.items() for t in ts), r)
    return [*runs, *_generated(sizes), control()]


def control() -> dict:
    """The AMR's 10-minute healthy run (every alert is a false one)."""
    return {"system": "amr", "fault": None, "target": None, "warmup": CONTROL_S, "post": 0.0, "control": True}


def _demo_short() -> list[dict]:
    from bench.eval.systems import pick_targets, system_topology

    runs = [{"system": "demo", "fault": f, "target": DEMO_SHORT[f]} for f in BASIC_FAULTS]
    runs.append({"system": "demo", "fault": None, "target": None})  # one: ~25 min in all
    target = pick_targets(system_topology("gen20", 1), 1)[0]
    return [*runs, {"system": "gen20", "seed": 1, "fault": "hang", "target": target}]


def _amr_runs(faults: Iterable[tuple[str, str]], rep: int) -> list[dict]:
    runs = [{"system": "amr", "fault": f, "target": t, "rep": rep} for f, t in faults]
    return [*runs, {"system": "amr", "fault": None, "target": None, "rep": rep}]


def _generated(sizes: Sequence[int]) -> list[dict]:
    from bench.eval.systems import LARGE, pick_targets, system_topology

    runs = []
    for n in sizes:
        topo = system_topology(f"gen{n}", 1)
        targets = pick_targets(topo, 1 if n >= LARGE else 2)  # a 500-node run takes ~2 min
        runs += [{"system": f"gen{n}", "seed": 1, "fault": f, "target": t}
                 for f in BASIC_FAULTS for t in targets]
        runs.append({"system": f"gen{n}", "seed": 1, "fault": None, "target": None})
    return runs


def run_id(spec: dict) -> str:
    """The folder name of a run: system, fault, target, size, repetition."""
    if spec.get("control"):
        return f"{spec['system']}_control_{spec['warmup'] + spec['post']:.0f}s_{spec.get('rep', 0)}"
    t = (spec.get("target") or "none").removeprefix("node:").strip("/").replace("/", ".")
    size = f"_s{spec['size']:g}" if spec.get("size") is not None else ""
    return f"{spec['system']}_{spec.get('fault') or 'nofault'}_{t}{size}_{spec.get('rep', 0)}"


def timeout(spec: dict) -> float:
    """Seconds a run may take in all (start-up, monitoring, re-ranks) before it is abandoned."""
    return 300.0 + float(spec.get("warmup", 20.0)) + float(spec.get("post", 25.0))
