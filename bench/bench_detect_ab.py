"""The detect step at 1,000 nodes, replayed, plugins inline: this tree against an earlier commit.

A generated 1,000-node system (2,149 members) is recorded healthy (`bench_replay.record`, no
crash) and replayed through the real `Monitor` with the default configuration (``auto`` watch
mode: above 2,000 members, processes and nodes), every plugin run inline (no worker thread, so
the process CPU around `Detector.detect` is the plugins' own). Base and this tree alternate, each
in its own process (a git worktree of ``--base`` first on PYTHONPATH); printed per run: the
detect step's process CPU per sample (mean over samples 5 on) and a digest of the report.

    .venv/bin/python bench/bench_detect_ab.py --base 14daaa5 --rounds 3
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))


def child(recording: Path) -> dict:
    from stream_viz.collect.replay import ReplayCollector
    from stream_viz.commands.replay import PLUGIN_TIMEOUT_S, replay_config
    from stream_viz.monitor import Monitor
    from stream_viz.progress import Progress

    with tempfile.TemporaryDirectory() as tmp:
        src = ReplayCollector(recording)
        mon = Monitor(replay_config(None, src.header), db=Path(tmp) / "a.sqlite", collector=src,
                      started_at=src.header.get("started_at"), plugin_timeout_s=PLUGIN_TIMEOUT_S,
                      progress=Progress(open(os.devnull, "w")))
        for p in mon.plugins.plugins:
            p.runner.isolate = False  # the plugins' CPU in this thread, not a worker's
        detect, cpu = mon.detector.detect, []

        def timed(*a, **kw):
            t0 = time.process_time()
            try:
                return detect(*a, **kw)
            finally:
                cpu.append(time.process_time() - t0)

        mon.detector.detect = timed
        while not src.done:
            mon.step()
        report = {k: v for k, v in mon.close().items() if k != "ended_at"}
    digest = hashlib.sha256(json.dumps(report, sort_keys=True, default=repr).encode()).hexdigest()
    return {"ms": 1e3 * statistics.fmean(cpu[5:]), "alerts": len(report["alerts"]), "digest": digest}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True)
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=90)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--child", type=Path, nargs=2, help=argparse.SUPPRESS)  # recording, output
    args = ap.parse_args(argv)
    if args.child:
        args.child[1].write_text(json.dumps(child(args.child[0])))
        return 0
    from bench_rca_update import code_path, unworktree, worktree
    from bench_replay import commit, record

    with tempfile.TemporaryDirectory(prefix="bench_detect_ab_") as t:
        tmp = Path(t)
        recording = tmp / "g.jsonl.gz"
        members, _, _ = record(args.nodes, args.samples, args.samples + 1, recording)
        print(f"commit {commit()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; "
              f"{args.nodes} nodes, {members} members, {args.samples} healthy samples; base {args.base}",
              flush=True)
        trees = {"base": worktree(args.base, tmp / "base"), "this": ROOT}
        got: dict[str, list[dict]] = {"base": [], "this": []}
        try:
            for i in range(args.rounds):
                for name in ("base", "this") if i % 2 == 0 else ("this", "base"):
                    out = tmp / f"{name}_{i}.json"
                    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--base", args.base,
                                    "--child", str(recording), str(out)],
                                   env=dict(os.environ, PYTHONPATH=code_path(trees[name], tmp)),
                                   cwd=trees[name], check=True)
                    got[name].append(json.loads(out.read_text()))
                    r = got[name][-1]
                    print(f"{name} (round {i + 1}): detect {r['ms']:.1f} ms a sample, {r['alerts']} alerts, "
                          f"digest {r['digest'][:16]}", flush=True)
        finally:
            unworktree(trees["base"])
        b, n = (statistics.median(r["ms"] for r in got[k]) for k in ("base", "this"))
        print(f"median: base {b:.1f}, this {n:.1f}, this / base {n / b:.2f}; reports identical: "
              f"{len({r['digest'] for v in got.values() for r in v}) == 1}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
