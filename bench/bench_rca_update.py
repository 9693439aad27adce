"""The RCA update alone at 2,000 members and ~1,000 alerts, on the inputs of a replayed run.

Issue 18's goal: an RCA update < 20 ms at 2,000 members and 1,000 alerts. A generated 1,000-node
system (2,149 members) is recorded without running it (`stream_viz.demo.synthetic`, as in
`bench_replay.py`: one sample a second, at ``--crash-at`` the process whose loss silences the
most topics is killed) and replayed through the real `Monitor` (``[watchlist] mode = "all"``)
once, with the code of ``--detect-at`` (a git worktree of it): issue 18's figure was taken at
``f603bf1``, whose detection stores 1,062 alerts by sample 77 of this run; today's detection
stores far fewer (192 in all), so the RCA's inputs come from that commit. Every call of
`RcaEngine.update` is captured with its inputs (the seen graph, the sample's stored alerts, the
evidence, the time, and the run's watchlist as it was before the call), and timed there too
(process CPU of every thread, as `bench_replay.py` times a step, and the calling thread's own).
Then a fresh engine of the code under test is fed those inputs in order, timing each update
alone (process CPU; a garbage collection before each call, so that another step's garbage is
not charged to it).

Printed: the sample at which ~1,000 alerts are stored, the update's mean and max over the next
10 samples and over all samples from the crash on, and a digest of every result (report,
incidents, ranked causes): two versions of the code that compute the same give the same digest;
then the same samples as timed inside the capturing replay.

    .venv/bin/python bench/bench_rca_update.py                      # this tree
    .venv/bin/python bench/bench_rca_update.py --base 14daaa5       # A/B: base and this tree alternately
    .venv/bin/python bench/bench_rca_update.py --profile            # cProfile of the measured updates
    .venv/bin/python bench/bench_rca_update.py --base 14daaa5 --live   # timed inside the replay instead
"""

from __future__ import annotations

import argparse
import gc
import gzip
import hashlib
import itertools
import json
import os
import pickle
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DETECT_AT = "f603bf1"  # issue 18's figure: its detection stores 1,062 alerts by sample 77
sys.path.insert(0, str(ROOT / "bench"))
from bench_scale_ab import code_path  # noqa: E402  (bench/ on the path first)


def capture(nodes: int, samples: int, crash_at: int, out: Path | None, live_out: Path) -> None:
    """Record the synthetic run and replay it; write every `RcaEngine.update` call's inputs to
    ``out`` (None: none) and, to ``live_out``, how long each call took there and its alerts."""
    from bench_replay import record, replay

    from stream_viz.rca import engine

    calls = gzip.open(out, "wb", compresslevel=1) if out is not None else None
    original = engine.RcaEngine.update
    live: list[tuple[float, float, int]] = []  # per call: process CPU (every thread), this thread's, alerts

    def spy(self, G, alerts, evidence=None, t=None):
        alerts = list(alerts)
        if calls is not None:
            pickle.dump((G, alerts, evidence, t, self.watchlist), calls, protocol=pickle.HIGHEST_PROTOCOL)
        p0, t0 = time.process_time(), time.thread_time()
        try:
            return original(self, G, alerts, evidence, t)
        finally:
            live.append((time.process_time() - p0, time.thread_time() - t0, len(alerts)))

    engine.RcaEngine.update = spy
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        path = work / "g.jsonl.gz"
        record(nodes, samples, crash_at, path)
        config = work / "watch.toml"
        config.write_text('[watchlist]\nmode = "all"\n')
        replay(path, work, crash_at, config)
    engine.RcaEngine.update = original
    if calls is not None:
        calls.close()
    live_out.write_text(json.dumps(live))


def live_path(calls: Path) -> Path:
    return calls.with_name(calls.name + ".live.json")


def live_line(calls: Path, detect_at: str, i: int, span: int = 10) -> str:
    """The update as timed inside the replay that captured the calls (``detect_at``'s RCA), from
    call ``i`` on."""
    live = json.loads(live_path(calls).read_text())
    proc, own = [1e3 * x[0] for x in live[i:i + span]], [1e3 * x[1] for x in live[i:i + span]]
    return (f"in the capturing replay ({detect_at}'s code, other threads running): RCA update "
            f"{statistics.fmean(proc):.1f} ms process CPU mean over the same samples, max {max(proc):.1f}; "
            f"its own thread {statistics.fmean(own):.1f} mean, max {max(own):.1f}")


def calls_of(path: Path):
    with gzip.open(path, "rb") as f:
        while True:
            try:
                yield pickle.load(f)
            except EOFError:
                return


def run(path: Path, profile: Path | None = None, alerts_at: int = 1000, span: int = 10) -> dict:
    """Feed a fresh engine the captured calls; return the times (s) per update and the digest."""
    from stream_viz.config import load_config
    from stream_viz.detect.watchlist import Watchlist
    from stream_viz.rca.engine import RcaEngine

    settings = load_config(None).rca
    np.unique(np.zeros(2))  # numpy imports numpy.ma on its first unique: a live monitor has done it
    engine = RcaEngine(settings, watchlist=Watchlist())
    digest = hashlib.sha256()
    cpu, stored, members, total = [], [], [], 0
    prof = None
    if profile is not None:
        import cProfile

        prof = cProfile.Profile()
    for G, alerts, evidence, t, watchlist in calls_of(path):
        engine.watchlist = watchlist  # the run's, as the other steps left it before this call
        total += len(alerts)
        gc.collect()
        measured = prof is not None and total >= alerts_at and sum(1 for n in stored if n >= alerts_at) < span
        if measured:
            prof.enable()
        t0 = time.process_time()
        result = engine.update(G, alerts, evidence, t=t)
        cpu.append(time.process_time() - t0)
        if measured:
            prof.disable()
        stored.append(total)
        members.append(G.number_of_nodes())
        report = result.to_report()
        report["incidents_full"] = [(i.id, i.start, i.end, i.ongoing, i.recurring, i.strength, i.first,
                                     i.current) for i in result.incidents]
        digest.update(json.dumps(report, sort_keys=True, default=repr).encode())
    if prof is not None:
        prof.dump_stats(str(profile))
    return {"cpu": cpu, "stored": stored, "members": members, "digest": digest.hexdigest()}


def summary(r: dict, crash_at: int, alerts_at: int = 1000, span: int = 10) -> dict:
    i = next((k for k, n in enumerate(r["stored"]) if n >= alerts_at), None)
    if i is None:
        raise SystemExit(f"never {alerts_at} alerts stored (at most {r['stored'][-1]})")
    xs = r["cpu"][i:i + span]
    after = r["cpu"][crash_at:]
    return {"sample": i, "members": r["members"][i], "alerts": r["stored"][i],
            "mean_ms": 1e3 * statistics.fmean(xs), "max_ms": 1e3 * max(xs),
            "faulted_mean_ms": 1e3 * statistics.fmean(after), "faulted_max_ms": 1e3 * max(after),
            "digest": r["digest"]}


def line(name: str, s: dict) -> str:
    return (f"{name}: {s['members']} members, {s['alerts']} alerts stored (sample {s['sample']}): RCA update "
            f"{s['mean_ms']:.1f} ms mean over the next 10 samples, max {s['max_ms']:.1f}; from the crash on "
            f"{s['faulted_mean_ms']:.1f} mean, max {s['faulted_max_ms']:.1f}; digest {s['digest'][:16]}")


def worktree(commit: str, where: Path) -> Path:
    subprocess.run(["git", "worktree", "add", "--detach", str(where), commit], cwd=ROOT, check=True,
                   capture_output=True)
    return where


def unworktree(where: Path) -> None:
    subprocess.run(["git", "worktree", "remove", "--force", str(where)], cwd=ROOT, capture_output=True)


def live_ab(args: argparse.Namespace, tmp: Path, span: int = 10) -> int:
    """The update timed inside the replay, base's RCA against this tree's, alternately."""
    trees = {}
    for name in ("base", "this"):
        tree = trees[name] = worktree(args.detect_at, tmp / f"live_{name}")
        shutil.rmtree(tree / "stream_viz" / "rca")
        if name == "this":
            shutil.copytree(ROOT / "stream_viz" / "rca", tree / "stream_viz" / "rca")
        else:
            tar = subprocess.run(["git", "archive", args.base, "stream_viz/rca"], cwd=ROOT, check=True,
                                 capture_output=True).stdout
            subprocess.run(["tar", "-x", "-C", str(tree)], input=tar, check=True)
    got: dict[str, list[tuple[float, float]]] = {"base": [], "this": []}
    try:
        for i in range(args.rounds):
            for name in ("base", "this") if i % 2 == 0 else ("this", "base"):
                out = tmp / f"live_{name}_{i}.json"
                subprocess.run([sys.executable, str(Path(__file__).resolve()), "--nodes", str(args.nodes),
                                "--samples", str(args.samples), "--crash-at", str(args.crash_at),
                                "--live-child", str(out)],
                               env=dict(os.environ, PYTHONPATH=code_path(trees[name], tmp)), cwd=trees[name],
                               check=True)
                live = json.loads(out.read_text())
                stored = list(itertools.accumulate(x[2] for x in live))
                k = next(j for j, n in enumerate(stored) if n >= 1000)
                xs = [1e3 * x[0] for x in live[k:k + span]]
                got[name].append((statistics.fmean(xs), max(xs)))
                print(f"{name} (round {i + 1}): {stored[k]} alerts stored (sample {k}): RCA update in the "
                      f"replay {got[name][-1][0]:.1f} ms process CPU mean over the next {len(xs)} samples, "
                      f"max {got[name][-1][1]:.1f}", flush=True)
    finally:
        for tree in trees.values():
            unworktree(tree)
    for f, label in ((0, "mean"), (1, "max")):
        b, n = (statistics.fmean(x[f] for x in got[k]) for k in ("base", "this"))
        print(f"{label}: base {b:.1f}, this {n:.1f}, this / base {n / b:.2f}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=90)
    ap.add_argument("--crash-at", type=int, default=40)
    ap.add_argument("--calls", type=Path, help="captured calls (written when missing; default: a temp file)")
    ap.add_argument("--base", help="an earlier commit: A/B, alternating, each in its own process")
    ap.add_argument("--rounds", type=int, default=2, help="A/B rounds")
    ap.add_argument("--profile", type=Path, nargs="?", const=Path("rca_update.prof"),
                    help="write a cProfile of the measured updates")
    ap.add_argument("--detect-at", default=DETECT_AT,
                    help="the commit whose detection makes the alerts (default %(default)s: ~1,000 alerts "
                         "by sample 77; today's detection raises far fewer on this recording)")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)  # write this run's summary as JSON
    ap.add_argument("--capture-child", type=Path, help=argparse.SUPPRESS)  # capture into this file
    ap.add_argument("--live-child", type=Path, help=argparse.SUPPRESS)  # time the live updates only
    ap.add_argument("--live", action="store_true",
                    help="with --base: time the update inside the replay instead, the Monitor of --detect-at "
                         "with the RCA (stream_viz/rca) of --base and of this tree")
    args = ap.parse_args(argv)
    from bench_replay import commit

    with tempfile.TemporaryDirectory(prefix="bench_rca_update_") as t:
        tmp = Path(t)
        calls = args.calls or tmp / "calls.pkl.gz"
        if args.child:
            args.child.write_text(json.dumps(summary(run(calls), args.crash_at)))
            return 0
        if args.capture_child:
            import stream_viz

            print(f"capturing with {Path(stream_viz.__file__).parent}", file=sys.stderr)
            out = args.capture_child
            capture(args.nodes, args.samples, args.crash_at, out, live_path(out))
            return 0
        if args.live_child:
            capture(args.nodes, args.samples, args.crash_at, None, args.live_child)
            return 0
        if args.live:
            return live_ab(args, tmp)
        if not calls.exists():
            t0 = time.monotonic()
            tree = worktree(args.detect_at, tmp / "detect")
            try:
                subprocess.run([sys.executable, str(Path(__file__).resolve()), "--nodes", str(args.nodes),
                                "--samples", str(args.samples), "--crash-at", str(args.crash_at),
                                "--capture-child", str(calls)],
                               env=dict(os.environ, PYTHONPATH=code_path(tree, tmp)), cwd=tree, check=True)
            finally:
                unworktree(tree)
            print(f"captured {args.nodes} nodes, {args.samples} samples, crash at {args.crash_at}, detection "
                  f"of {args.detect_at} ({time.monotonic() - t0:.0f} s, {calls.stat().st_size / 1e6:.0f} MB)",
                  file=sys.stderr)
        print(f"commit {commit()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; "
              f"{' '.join(sys.argv)}")
        if not args.base:
            sm = summary(run(calls, args.profile), args.crash_at)
            print(line("this", sm))
            if live_path(calls).exists():
                print(live_line(calls, args.detect_at, sm["sample"]))
            return 0
        base = worktree(args.base, tmp / "base")
        try:
            got: dict[str, list[dict]] = {"base": [], "this": []}
            for i in range(args.rounds):
                order = [("base", base), ("this", ROOT)] if i % 2 == 0 else [("this", ROOT), ("base", base)]
                for name, tree in order:
                    out = tmp / f"{name}_{i}.json"
                    env = dict(os.environ, PYTHONPATH=code_path(tree, tmp))
                    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--calls", str(calls),
                                    "--crash-at", str(args.crash_at), "--child", str(out)],
                                   env=env, cwd=tree, check=True)
                    got[name].append(json.loads(out.read_text()))
                    print(line(f"{name} (round {i + 1})", got[name][-1]), flush=True)
        finally:
            unworktree(base)
        mean = {k: {f: statistics.fmean(s[f] for s in v) for f in ("mean_ms", "max_ms", "faulted_mean_ms")}
                for k, v in got.items()}
        for f in ("mean_ms", "max_ms", "faulted_mean_ms"):
            print(f"{f}: base {mean['base'][f]:.1f}, this {mean['this'][f]:.1f}, "
                  f"this / base {mean['this'][f] / mean['base'][f]:.2f}")
        if live_path(calls).exists():
            print(live_line(calls, args.detect_at, got["this"][0]["sample"]))
        digests = {s["digest"] for v in got.values() for s in v}
        print(f"results identical (one digest over every update of both versions): {len(digests) == 1}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
