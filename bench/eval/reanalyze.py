"""Re-rank a finished suite's runs with today's RCA: the same alerts, the current code.

``python -m bench.eval.reanalyze bench/out/short --csv bench/results/<suite>-<commit>/reanalysis-<code>.csv``

For every faulty run of ``runs.jsonl`` in the suite's output folder, reads the run's alert
database (model snapshot, alerts, watchlist) as ``stream-viz analyze`` does, ranks with the
default settings, and scores the ranking against the run's truth (strict and process level,
ties as expected values, as `bench.eval.metrics`). With ``--replay``, the run's recorded samples
(a suite run with ``--samples``) go through today's detection and RCA instead (``stream-viz
replay``: the live pipeline, process-monitoring evidence included). Writes one CSV row per run
and prints the means per system. The live ranking of the run is in the CSV beside it.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.eval.metrics import hit_at, tie_blocks
from bench.eval.provenance import code_version
from bench.eval.suites import run_id
from stream_viz.commands.analyze import read_run
from stream_viz.rca import RcaSettings
from stream_viz.rca.engine import analyze


def blocks_of(ranked: list) -> list[tuple[str, ...]]:
    """A ranking as tie blocks (tuples), whether members come alone or as tied lists."""
    return [(x,) if isinstance(x, str) else tuple(x) for x in ranked]


def rerank(db: Path) -> list:
    """Today's ranking of the run in ``db``, ties as tuples (`bench.eval.metrics.tie_blocks`)."""
    G, alerts, watch, *_ = read_run(db)
    result = analyze(G, alerts, RcaSettings(), set(watch) if watch else None)
    return tie_blocks((rc.member, round(rc.score, 6)) for rc in result.root_causes)


def replay_report(samples: Path, config: str | None = None, healthy: Path | None = None) -> dict:
    """The JSON report of ``stream-viz replay`` over the run recorded in ``samples`` (``config``:
    the text of a settings file to replay with; ``healthy``: the database of a healthy run to
    start from, ``--healthy``)."""
    with tempfile.TemporaryDirectory() as d:
        report = Path(d) / "report.json"
        extra = []
        if config is not None:
            (Path(d) / "config.toml").write_text(config)
            extra = ["--config", str(Path(d) / "config.toml")]
        if healthy is not None:
            extra += ["--healthy", str(healthy)]
        subprocess.run([sys.executable, "-m", "stream_viz.cli", "replay", str(samples), "--viewer", "none",
                        "--report", str(report), "--db", str(Path(d) / "alerts.sqlite"), *extra],
                       check=True, capture_output=True, timeout=1800)
        return json.loads(report.read_text())


def replayed(samples: Path) -> list:
    """Today's live diagnosis of the run recorded in ``samples``: its final ranking, ties as tuples."""
    causes = replay_report(samples)["root_causes"]
    return tie_blocks((rc["member"], round(rc["score"], 6)) for rc in causes)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="the suite's output folder (runs.jsonl, a folder per run)")
    ap.add_argument("--csv", type=Path, required=True, help="where to write one row per run")
    ap.add_argument("--replay", action="store_true",
                    help="replay each run's samples.jsonl.gz through today's detection and RCA")
    args = ap.parse_args(argv)
    rows = []
    for line in (args.out / "runs.jsonl").read_text().splitlines():
        run = json.loads(line)
        if not run.get("injected"):
            continue
        spec = run["spec"]
        db = args.out / run_id(spec) / "alerts.sqlite"
        samples = db.parent / "samples.jsonl.gz"
        if not (samples if args.replay else db).exists():
            continue
        now = blocks_of(replayed(samples) if args.replay else rerank(db))
        live = blocks_of(run["rankings"]["live"])
        strict, proc = set(run["truth_strict"]), set(run["truth_process"])
        rows.append({"run": db.parent.name, "system": spec["system"], "fault": spec["fault"],
                     "target": spec["target"],
                     "live_top": " ".join("|".join(b) for b in live[:1]),
                     "now_top": " ".join("|".join(b) for b in now[:1]),
                     "live_ac1_strict": hit_at(live, strict, 1), "now_ac1_strict": hit_at(now, strict, 1),
                     "live_ac1_process": hit_at(live, proc, 1), "now_ac1_process": hit_at(now, proc, 1),
                     "now_ac3_strict": hit_at(now, strict, 3)})
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    with args.csv.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"code {code_version()['commit']}; {len(rows)} runs -> {args.csv}")
    for system in sorted({r["system"] for r in rows}):
        rs = [r for r in rows if r["system"] == system]
        keys = ("live_ac1_strict", "now_ac1_strict", "live_ac1_process", "now_ac1_process", "now_ac3_strict")
        mean = {k: sum(r[k] for r in rs) / len(rs) for k in keys}
        print(system, len(rs), " ".join(f"{k}={v:.2f}" for k, v in mean.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
