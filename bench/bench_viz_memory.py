"""Memory of the monitor's recording side over a long run: fixed 5 s metric batches, bounded chunks/s,
and bounded chunks/s saved in 10-minute file parts.

Rerun keeps an index entry for every chunk written to an ``.rrd`` (the file's footer) in memory
until the file is closed, and every metric batch is one chunk per member: on a large system the
recording alone grows the monitor by megabytes per minute. This runs the real `LiveView`
(``--save`` to a real ``.rrd``) on a synthetic system (``chain_graph``: ``--nodes`` nodes, one
topic each, 50 processes) for ``--minutes`` simulated minutes at 1 Hz, θ changing every sample,
once per policy, each in its own process so RSS is its own, side by side in one run:

- ``fixed``: a batch every 5 s whatever the size (``max_chunks_per_s = 0``, the old behaviour);
- ``bounded``: at most 20 metric chunks per second (`stream_viz.viz.live.metrics_batch_s`);
- ``parts``: bounded, and a new file part every 10 minutes (the default
  ``[monitor] recording_part_minutes``), which frees the index of the closed part.

    .venv/bin/python bench/bench_viz_memory.py --nodes 500 --minutes 30
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

POLICIES = {"fixed": (0.0, 0.0), "bounded": (20.0, 0.0), "parts": (20.0, 600.0)}  # (chunks/s, part s)


def one(nodes: int, minutes: float, policy: tuple[float, float], rrd: Path) -> dict:
    import gc

    import numpy as np
    import psutil

    from stream_viz.rca.engine import RcaEngine
    from stream_viz.rca.settings import RcaSettings
    from stream_viz.records import Sample
    from stream_viz.viz.live import LiveView
    from stream_viz.viz.sample import chain_graph, set_theta

    me = psutil.Process()
    G = chain_graph(nodes)
    rng = np.random.default_rng(0)
    view = LiveView(save=rrd, max_chunks_per_s=policy[0], part_s=policy[1])
    result = RcaEngine(RcaSettings(), watchlist=None).update(G, [])
    curve = []
    ticks = int(minutes * 60)
    for i in range(ticks):
        t = 1.7e9 + i
        set_theta(G, rng)
        view.update(t, Sample(t, G.copy()), G, [], result)
        if i % 60 == 0 or i == ticks - 1:
            gc.collect()
            curve.append((i / 60, me.memory_info().rss / 2**20))
    view.close()
    parts = view.recording_parts
    return {"curve": curve, "rrd_mb": sum(p.stat().st_size for p in parts) / 2**20, "parts": len(parts)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--nodes", type=int, default=500)
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--policy", choices=list(POLICIES), help=argparse.SUPPRESS)  # the child
    ap.add_argument("--rrd", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.policy:
        print(json.dumps(one(args.nodes, args.minutes, POLICIES[args.policy], args.rrd)))
        return 0
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in POLICIES:
            cmd = [sys.executable, __file__, "--nodes", str(args.nodes), "--minutes", str(args.minutes),
                   "--policy", name, "--rrd", str(Path(tmp) / f"{name}.rrd")]
            res = subprocess.run(cmd, capture_output=True, text=True, check=True,
                                 env=dict(os.environ, RERUN_TELEMETRY_ENABLED="false", CI="1"))
            out[name] = json.loads(res.stdout.strip().splitlines()[-1])
    print(f"recording memory: {args.nodes}-node synthetic system, {args.minutes:g} simulated min at 1 Hz, "
          f".rrd written, {os.cpu_count()} cores")
    print(f"{'policy':8s} {'RSS start MB':>12s} {'at 5 min':>9s} {'end':>7s} {'peak':>7s} "
          f"{'MB/min after 5':>15s} {'.rrd MB':>8s} {'files':>5s}")
    for name, r in out.items():
        c = r["curve"]
        at5 = next((mb for m, mb in c if m >= 5), c[-1][1])
        slope = (c[-1][1] - at5) / max(c[-1][0] - 5, 1e-9)
        peak = max(mb for _, mb in c)
        print(f"{name:8s} {c[0][1]:12.1f} {at5:9.1f} {c[-1][1]:7.1f} {peak:7.1f} {slope:15.2f} "
              f"{r['rrd_mb']:8.1f} {r['parts']:5d}")
    f = out["fixed"]["curve"]

    def growth(name: str) -> float:
        c = out[name]["curve"]
        return (c[-1][1] - c[0][1]) / max(f[-1][1] - f[0][1], 1e-9)

    print(f"growth vs fixed: bounded {growth('bounded'):.2f}, parts {growth('parts'):.2f}; "
          f".rrd vs fixed: bounded {out['bounded']['rrd_mb'] / out['fixed']['rrd_mb']:.2f}, "
          f"parts {out['parts']['rrd_mb'] / out['fixed']['rrd_mb']:.2f}")
    print("curves (minute, RSS MB): " + json.dumps({k: [(round(m, 1), round(mb, 1)) for m, mb in v["curve"]]
                                                  for k, v in out.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
