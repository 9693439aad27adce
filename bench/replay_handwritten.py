"""Replay a handwritten robot's recorded runs through today's detection and RCA, and score them.

``python -m bench.replay_handwritten RUNS.jsonl SAMPLES_DIR --csv OUT.csv``

For the runs of a ``bench.<robot>.run --samples SAMPLES_DIR`` suite (`bench.handwritten`: the
sim rover, the field robot, the station, the lab; the newest line per run name), each run's
``<run>.jsonl.gz`` goes through ``stream-viz replay`` (the live pipeline, as fast as it goes).
Writes one row per run: the alerts, those before the injection, the first alert after it (s; as
the live runner counts them, an alert up to ``SLACK_S`` before it is its sample's),
the top 3 and the truth, strict and process-level AC@1 and strict AC@3 (ties as expected values,
as `bench.eval.metrics`); prints the means, the median first alert and the healthy run's alerts.
``--healthy RUN.sqlite`` starts each replay from what that healthy run learned (``stream-viz
--healthy``).
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
from pathlib import Path

from bench.eval.metrics import hit_at, tie_blocks
from bench.eval.provenance import code_version
from bench.eval.reanalyze import replay_report
from bench.handwritten import SLACK_S

FIELDS = ["run", "code", "alerts", "before_injection", "first_alert_s", "top3", "truth", "ac1_strict",
          "ac3_strict", "ac1_process"]


def score(run: dict, report: dict, code: str) -> dict:
    """One CSV row: ``run`` (a runs.jsonl line) scored on the replay's ``report``."""
    name = run.get("fault") or "healthy"
    alerts = report["alerts"]
    at = run.get("injected_at")
    before = [a for a in alerts if at is not None and a["t"] < at - SLACK_S]
    after = sorted(a["t"] - at for a in alerts if at is not None and a["t"] >= at - SLACK_S)
    ranked = [(x,) if isinstance(x, str) else tuple(x)
              for x in tie_blocks((c["member"], round(c["score"], 6)) for c in report["root_causes"])]
    truth = run.get("truth") or {}
    strict = {f"node:{truth['strict']}"} if truth.get("strict") else set()
    process = {f"node:{n}" for n in truth.get("process", ())}
    row = {"run": name, "code": code, "alerts": len(alerts), "before_injection": len(before),
           "first_alert_s": f"{after[0]:.1f}" if after else "",
           "top3": " ".join("|".join(b) for b in ranked[:3]), "truth": truth.get("strict", "")}
    if strict:
        row |= {"ac1_strict": hit_at(ranked, strict, 1), "ac3_strict": hit_at(ranked, strict, 3),
                "ac1_process": hit_at(ranked, process, 1)}
        row |= {k: round(row[k], 3) for k in FIELDS[-3:]}  # 0.2, not 0.19999999999999996
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, help="the suite's runs.jsonl")
    ap.add_argument("samples", type=Path, help="its --samples folder (<run>.jsonl.gz)")
    ap.add_argument("--csv", type=Path, required=True)
    ap.add_argument("--healthy", type=Path, metavar="RUN.sqlite",
                    help="start every replay from this healthy run's database (stream-viz --healthy)")
    args = ap.parse_args(argv)
    newest = {}
    for line in args.runs.read_text().splitlines():
        run = json.loads(line)
        newest[run.get("fault") or "healthy"] = run  # a run repeated in the folder: its last
    version = code_version()
    code = version["commit"][:7] + ("+dirty" if version["dirty"] else "")  # uncommitted code says so
    rows = []
    for name, run in newest.items():
        samples = args.samples / f"{name}.jsonl.gz"
        if samples.exists():
            rows.append(score(run, replay_report(samples, healthy=args.healthy), code))
            print(rows[-1], flush=True)
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    with args.csv.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)
    faults = [r for r in rows if "ac1_strict" in r]
    if faults:
        mean = {k: sum(r[k] for r in faults) / len(faults) for k in FIELDS[-3:]}
        seen = [float(r["first_alert_s"]) for r in faults if r["first_alert_s"]]
        print(f"code {code}; {len(faults)} faults: " + " ".join(f"{k}={v:.2f}" for k, v in mean.items())
              + f"; median first alert {statistics.median(seen) if seen else float('nan'):.1f} s"
              f" ({len(seen)} of {len(faults)} seen); before any injection "
              f"{sum(r['before_injection'] for r in faults)}")
    for r in rows:
        if "ac1_strict" not in r:
            print(f"{r['run']}: {r['alerts']} alerts")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
