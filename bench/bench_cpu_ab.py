"""The monitor's CPU on a demo robot (``--robot``), this tree against an earlier commit, interleaved.

Each round runs `bench_monitor_cpu.py --no-stages` (phase 1: CPU per thread over ``--seconds``,
own demo robot, own ROS_DOMAIN_ID) once with the code of ``--base`` (a git worktree of that
commit put first on PYTHONPATH; this tree's bench script and plugins) and once with this tree,
alternating which goes first. The machine is shared and drifts: read the per-round ratios.

    .venv/bin/python bench/bench_cpu_ab.py --base 9cd4bbe --rounds 3 --seconds 40
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench.eval.provenance import short_version  # noqa: E402


def run_once(code_root: Path, seconds: float, out: Path, fault: str | None, robot: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code_root))
    subprocess.run([sys.executable, str(ROOT / "bench/bench_monitor_cpu.py"), "--no-stages", "--robot", robot,
                    "--seconds", str(seconds), "--json", str(out), *(["--fault", fault] if fault else [])],
                   env=env, cwd=code_root, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return json.loads(out.read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--base", required=True, help="the earlier commit")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--fault", metavar="KIND:NODE", help="a demo fault injected after the warm-up")
    ap.add_argument("--robot", default="demo", help="the demo robot monitored (demo, amr)")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="bench_cpu_ab_"))
    base = tmp / "base"
    subprocess.run(["git", "worktree", "add", "--detach", str(base), args.base], cwd=ROOT, check=True,
                   capture_output=True)
    # The ROS helpers the bench script starts with are tooling, not code under test; a base from
    # before stream_viz/testing.py existed gets this tree's.
    if not (base / "stream_viz/testing.py").exists():
        shutil.copy(ROOT / "stream_viz/testing.py", base / "stream_viz/testing.py")
    try:
        print(f"monitor CPU on the {args.robot} robot, % of one core over {args.seconds:.0f} s, fault "
              f"{args.fault or 'none'}: {args.base} vs this tree ({short_version(ROOT)})")
        print(f"{'round':>5s} {'base':>7s} {'this':>7s} {'ratio':>6s}   {'base main/native':>17s} "
              f"{'this main/native':>17s}  load")
        ratios = []
        for i in range(args.rounds):
            order = [("base", base), ("this", ROOT)] if i % 2 == 0 else [("this", ROOT), ("base", base)]
            got = {name: run_once(root, args.seconds, tmp / f"{name}_{i}.json", args.fault, args.robot)
                   for name, root in order}
            pct = {k: v["total_pct"] for k, v in got.items()}
            split = {k: "{:.2f}/{:.2f}".format(*(100 * v["cpu_s"].get(g, 0.0) / v["wall_s"] for g in (
                "main loop (Monitor.step)", "native (rclpy / Fast DDS)"))) for k, v in got.items()}
            ratios.append(pct["this"] / pct["base"])
            for name, root in order:  # the code that ran is the one asked for
                assert got[name]["code"].startswith(str(root)), got[name]["code"]
            print(f"{i + 1:5d} {pct['base']:6.2f}% {pct['this']:6.2f}% {ratios[-1]:6.2f}   "
                  f"{split['base']:>17s} {split['this']:>17s}  {got['this']['load']:.1f}", flush=True)
        print(f"median ratio this/base: {statistics.median(ratios):.2f}")
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
