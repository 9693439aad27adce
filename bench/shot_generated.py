"""A real diagnosis of a generated N-node system, recorded and rendered by the headless viewer.

``.venv/bin/python bench/shot_generated.py --nodes 100 --png docs/img/viz_gen100.png``

Starts the generated layered system (`stream_viz.demo.generated`, seed 0) in real rclpy
processes on a private ROS domain, monitors it with a recording, hangs the node with the most
downstream nodes after ``--warmup`` seconds, goes on for ``--post`` seconds, and renders the end
of the recording at 1600×900 with the default blueprint (`stream_viz.viz.screenshot`). Prints
the top root causes and the paths written.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
from pathlib import Path

from bench.eval.systems import pick_targets, system_topology
from stream_viz.config import load_config
from stream_viz.demo.robot import FaultSpec, Robot
from stream_viz.monitor import Monitor
from stream_viz.testing import own_domain
from stream_viz.viz.screenshot import screenshot


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=100)
    ap.add_argument("--png", type=Path, required=True)
    ap.add_argument("--rrd", type=Path, help="keep the recording here (default: a temporary file)")
    ap.add_argument("--warmup", type=float, default=25.0)
    ap.add_argument("--post", type=float, default=20.0)
    args = ap.parse_args(argv)
    domain = own_domain()
    topo = system_topology(f"gen{args.nodes}")
    target = pick_targets(topo, 1)[0]
    tmp = Path(tempfile.mkdtemp(prefix="stream_shot_"))
    rrd = args.rrd or tmp / "run.rrd"
    mon = Monitor(load_config(None), save=rrd, viewer="none", domain_id=domain)
    robot = Robot(env=dict(os.environ), topology=topo, run_dir=tmp / "robot")
    try:
        robot.start()
        robot.wait_ready(timeout=120.0 + 0.5 * len(topo.node_names()))
        robot.inject(FaultSpec("hang", target, args.warmup))
        mon.run(args.warmup + args.post, threading.Event())
    finally:
        mon.close()
        robot.stop()
    for rc in mon.engine.result().root_causes[:3]:
        print(f"{rc.member}  score {rc.score:.2f}")
    print(f"hang injected in {target}; recording {rrd}")
    print(f"screenshot {screenshot(rrd, args.png, settle=6.0)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
