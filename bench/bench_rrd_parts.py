"""Rerun's side of a long recording, with no stream-viz code: why `.rrd` parts, and why a stream each.

Two side-by-side measurements on the bare SDK (rerun-sdk), each case in its own process so RSS is
its own:

1. **memory**: ``--chunks`` one-row ``send_columns`` chunks to a ``FileSink``, all in one file
   (``one``) vs a new file every ``--part`` chunks (``parts``). Rerun keeps an index entry per
   chunk written to a file until it is closed; a new part frees the closed one's.
2. **switching to the next part with a viewer that went away** (a ``GrpcSink`` to a port nobody
   listens on): ``shared`` swaps the sinks of one stream that tees viewer and file (the viewer's
   sink is flushed first), ``own`` swaps only the file stream's sink (`stream_viz.viz.recorder`).

    .venv/bin/python bench/bench_rrd_parts.py
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DEAD_VIEWER = "rerun+http://127.0.0.1:9/proxy"  # port 9 (discard): nothing answers there


def memory(case: str, chunks: int, part: int, out: Path) -> dict:
    import numpy as np
    import psutil
    import rerun as rr

    me = psutil.Process()
    rec = rr.RecordingStream("bench_rrd_parts")
    rec.set_log_time_enabled(False)
    rec.set_sinks(rr.FileSink(str(out / "part0.rrd")))
    start = me.memory_info().rss / 2**20
    for i in range(chunks):
        rec.send_columns(f"/m/{i % 500}", indexes=[rr.TimeColumn("time", timestamp=np.array([i * 0.05]))],
                         columns=rr.Scalars.columns(scalars=np.array([float(i)])))
        if case == "parts" and i and i % part == 0:
            rec.flush(timeout_sec=10)
            rec.set_sinks(rr.FileSink(str(out / f"part{i // part}.rrd")))
    rec.flush(timeout_sec=10)
    return {"rss_start_mb": start, "rss_end_mb": me.memory_info().rss / 2**20,
            "files": len(list(out.glob("*.rrd")))}


def switch(case: str, parts: int, out: Path) -> dict:
    import rerun as rr

    rid = "bench-rrd-parts"
    live = rr.RecordingStream("bench_rrd_parts", recording_id=rid)
    file = live if case == "shared" else rr.RecordingStream("bench_rrd_parts", recording_id=rid)
    if case == "shared":
        live.set_sinks(rr.GrpcSink(DEAD_VIEWER), rr.FileSink(str(out / "p0.rrd")))
    else:
        live.set_sinks(rr.GrpcSink(DEAD_VIEWER))
        file.set_sinks(rr.FileSink(str(out / "p0.rrd")))
    took = []
    for n in range(1, parts + 1):
        for s in {id(live): live, id(file): file}.values():
            s.log("/x", rr.Scalars([float(n)]))
        t0 = time.perf_counter()
        if case == "shared":
            try:
                live.flush(timeout_sec=5.0)
            except Exception:  # the dead viewer's sink cannot flush
                pass
            live.set_sinks(rr.GrpcSink(DEAD_VIEWER), rr.FileSink(str(out / f"p{n}.rrd")))
        else:
            file.flush(timeout_sec=5.0)
            file.set_sinks(rr.FileSink(str(out / f"p{n}.rrd")))
        took.append(time.perf_counter() - t0)
    return {"switch_s": took}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--chunks", type=int, default=200_000)
    ap.add_argument("--part", type=int, default=20_000, help="chunks per file part (case parts)")
    ap.add_argument("--switches", type=int, default=3)
    ap.add_argument("--case", help=argparse.SUPPRESS)  # the child: memory:one, switch:own, …
    args = ap.parse_args(argv)
    if args.case:
        what, case = args.case.split(":")
        with tempfile.TemporaryDirectory() as tmp:
            res = (memory(case, args.chunks, args.part, Path(tmp)) if what == "memory"
                   else switch(case, args.switches, Path(tmp)))
        print(json.dumps(res))
        return 0
    env = dict(os.environ, CI="1", TELEMETRY_ENABLED="false")
    res = {}
    for case in ("memory:one", "memory:parts", "switch:shared", "switch:own"):
        cmd = [sys.executable, __file__, "--case", case, "--chunks", str(args.chunks), "--part",
               str(args.part), "--switches", str(args.switches)]
        done = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
        res[case] = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"bare rerun-sdk, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    print(f"memory, {args.chunks:,} one-row chunks:")
    grown = {}
    for case in ("one", "parts"):
        r = res[f"memory:{case}"]
        grown[case] = r["rss_end_mb"] - r["rss_start_mb"]
        print(f"  {case:6s} RSS {r['rss_start_mb']:6.1f} -> {r['rss_end_mb']:6.1f} MB  "
              f"(+{grown[case]:.1f}) in {r['files']} file(s)")
    print(f"  growth parts/one: {grown['parts'] / max(grown['one'], 1e-9):.2f}")
    print("switch to the next part, viewer gone (s per switch):")
    for case in ("shared", "own"):
        took = res[f"switch:{case}"]["switch_s"]
        print(f"  {case:6s} " + "  ".join(f"{x:.2f}" for x in took))
    return 0


if __name__ == "__main__":
    sys.exit(main())
