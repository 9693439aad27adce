"""The fault-injection evaluation: plan the runs, run them one after the other, run the peers, report.

``python -m bench.eval.run --short`` (~25 min), ``--full`` (hours), ``--control`` (the AMR's 10-minute
healthy run), ``--sweep`` (fault sizes, ~35 min); ``--report-only`` rescores what is already in the
output folder. Each run is its own process (bench.eval.run_one); the peers run in
``bench/.peers-venv``. Results: ``<out>/results.md``, ``scores.csv``, ``summary.json``, ``runs.jsonl``;
``--results DIR`` also writes the small files to ``DIR/<suite>-<commit>/`` (committed in the repo).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from bench.eval.publish import publish
from bench.eval.results import results_md, summary
from bench.eval.score import latencies, score_run
from bench.eval.suites import plan, run_id, timeout

ROOT = Path(__file__).resolve().parents[2]
PEER_PY = ROOT / "bench/.peers-venv/bin/python"
SUITES = ("short", "full", "control", "sweep")

__all__ = ["plan", "report", "run_id"]


def execute(specs: list[dict], out: Path, peers: bool = True) -> None:
    """Run every spec not yet done (``run.json`` present), one at a time."""
    for i, spec in enumerate(specs, 1):
        d = out / run_id(spec)
        if (d / "run.json").exists():
            continue
        t0 = time.time()
        print(f"[{i}/{len(specs)}] {run_id(spec)}  load {os.getloadavg()[0]:.1f}", flush=True)
        d.mkdir(parents=True, exist_ok=True)
        with open(d / "log.txt", "w") as log:
            try:
                rc = subprocess.run(
                    [sys.executable, "-m", "bench.eval.run_one", "--spec", json.dumps(spec), "--out", str(d)],
                    cwd=ROOT,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    timeout=timeout(spec),
                ).returncode
            except subprocess.TimeoutExpired:
                rc = "timeout"
        print(f"    done rc={rc} in {time.time() - t0:.0f} s", flush=True)
    todo = [
        str(out / run_id(s))
        for s in specs
        if (out / run_id(s) / "run.json").exists() and not (out / run_id(s) / "peers.json").exists()
    ]
    if todo and peers and PEER_PY.exists():
        print(f"peers on {len(todo)} runs …", flush=True)
        subprocess.run([str(PEER_PY), str(ROOT / "bench/eval/peers.py"), *todo], cwd=ROOT, timeout=3600)


def load(out: Path) -> list[tuple[dict, dict | None]]:
    runs = []
    for d in sorted(out.iterdir()):
        if (d / "run.json").exists():
            peers = json.loads((d / "peers.json").read_text()) if (d / "peers.json").exists() else None
            runs.append((json.loads((d / "run.json").read_text()), peers))
    return runs


def report(out: Path) -> str:
    """Score every recorded run; write ``scores.csv``, ``summary.json`` and ``results.md``; return the md."""
    runs = load(out)
    rows = [row for run, peers in runs for row in score_run(run, peers)]
    if rows:
        _write_scores(out / "scores.csv", rows)
    text = results_md(runs, rows)
    (out / "results.md").write_text(text)
    (out / "summary.json").write_text(json.dumps(summary(runs, rows)))
    _write_runs_jsonl(out / "runs.jsonl", runs)
    return text


def _write_scores(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _write_runs_jsonl(path: Path, runs: list[tuple[dict, dict | None]]) -> None:
    with open(path, "w") as f:  # one line per run, without the per-tick trace
        for run, peers in runs:
            slim = {k: v for k, v in run.items() if k not in ("ticks", "expand")}
            f.write(json.dumps({**slim, "latency": latencies(run) if run["spec"].get("fault") else None,
                                "peers": peers}) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    g = ap.add_mutually_exclusive_group()
    for suite in SUITES:
        g.add_argument(f"--{suite}", action="store_const", const=suite, dest="suite")
    ap.add_argument("--out", type=Path, help="output folder (default bench/out/<suite>)")
    ap.add_argument("--warmup", type=float, help="s from ready to the injection (default 20; AMR 25)")
    ap.add_argument("--post", type=float, help="s monitored after the injection (default 25; AMR 20)")
    ap.add_argument("--sizes", default="20,100", help="generated system sizes for --full (e.g. 20,100,500)")
    ap.add_argument("--reps", type=int, help="repetitions in --full (default 3) and --sweep (default 1)")
    ap.add_argument("--only", help="run only these systems (comma list: demo, amr, gen100)")
    ap.add_argument("--kinds", help="run only these fault kinds (comma list: leak,cpu; none: fault-free)")
    ap.add_argument("--report-only", action="store_true", help="rescore what is in --out")
    ap.add_argument("--no-peers", action="store_true",
                    help="do not run the peers (a later call without it runs them on these runs)")
    ap.add_argument("--samples", action="store_true",
                    help="record each run's samples.jsonl.gz (for stream-viz replay)")
    ap.add_argument("--plots", type=Path, help="write eval_*.png here (peer venv matplotlib)")
    ap.add_argument("--results", type=Path,
                    help="also write the small result files to RESULTS/<suite>-<commit>/ (bench/results)")
    args = ap.parse_args(argv)
    suite = args.suite or "short"
    out = args.out or ROOT / "bench/out" / suite
    out.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        sizes = [int(x) for x in args.sizes.split(",") if x]
        reps = args.reps or (1 if suite == "sweep" else 3)
        specs = plan(suite, args.warmup, args.post, sizes, reps)
        if args.only:
            specs = [s for s in specs if s["system"] in args.only.split(",")]
        if args.kinds:
            specs = [s for s in specs if (s["fault"] or "none") in args.kinds.split(",")]
        if args.samples:
            specs = [{**s, "samples": True} for s in specs]
        execute(specs, out, peers=not args.no_peers)
    print(report(out))
    if args.results:
        print(f"results: {publish(out, suite, args.results, argv if argv is not None else sys.argv[1:])}")
    if args.plots and suite in ("short", "full") and PEER_PY.exists():  # the plots show accuracy
        subprocess.run(
            [str(PEER_PY), str(ROOT / "bench/eval/plots.py"), str(out / "summary.json"), str(args.plots)],
            cwd=ROOT,
            check=False,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
