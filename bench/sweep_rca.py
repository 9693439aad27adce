"""Sweep one RCA setting over the committed recordings of the hand-written robots, and score it.

``python -m bench.sweep_rca incident_lead 5 10 20 30 --csv bench/results/<name>/sweep.csv``

Every suite folder under ``bench/results/`` with a ``runs.jsonl`` (each run's truth) and a
``samples/`` folder (``<run>.jsonl.gz``, `bench.replay_handwritten`) is replayed through
``stream-viz replay`` once per value, with ``[rca] <setting> = <value>`` as the only setting
changed (two replays at a time). One CSV row per suite, run and value, scored as
`bench.replay_handwritten.score` does; prints per value the means over every fault run (strict
AC@1, AC@3, process AC@1), the alerts of the healthy runs and those before the injections.
"""

from __future__ import annotations

import argparse
import csv
import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from bench.eval.provenance import code_version
from bench.eval.reanalyze import replay_report
from bench.replay_handwritten import FIELDS, score

RESULTS = Path(__file__).resolve().parent / "results"


def suites(root: Path = RESULTS) -> list[tuple[str, dict[str, dict], Path]]:
    """(suite name, run name → its newest runs.jsonl line, samples folder) of every labelled suite."""
    out = []
    for runs in sorted(root.glob("*/runs.jsonl")):
        samples = runs.parent / "samples"
        if not samples.is_dir():
            continue
        newest = {}
        for line in runs.read_text().splitlines():
            run = json.loads(line)
            newest[run.get("fault") or "healthy"] = run
        newest = {k: v for k, v in newest.items() if (samples / f"{k}.jsonl.gz").exists()}
        if newest:
            out.append((runs.parent.name, newest, samples))
    return out


def replay(samples: Path, setting: str, value: str) -> dict:
    """The report of ``stream-viz replay`` over ``samples`` with ``[rca] setting = value``."""
    return replay_report(samples, f"[rca]\n{setting} = {value}\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("setting", help="a key of the [rca] table (docs/rca.md, Settings)")
    ap.add_argument("values", nargs="+", help="TOML values to try")
    ap.add_argument("--csv", type=Path, required=True)
    args = ap.parse_args(argv)
    version = code_version()
    code = version["commit"][:7] + ("+dirty" if version["dirty"] else "")
    jobs = [(name, run_name, run, samples / f"{run_name}.jsonl.gz", v)
            for v in args.values for name, runs, samples in suites() for run_name, run in runs.items()]
    with ThreadPoolExecutor(2) as pool:
        reports = list(pool.map(lambda j: replay(j[3], args.setting, j[4]), jobs))
    rows = [{"suite": name, args.setting: v, **score(run, rep, code)}
            for (name, _, run, _, v), rep in zip(jobs, reports, strict=True)]
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    with args.csv.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["suite", args.setting, *FIELDS])
        w.writeheader()
        w.writerows(rows)
    print(f"code {code}; {len({r['suite'] for r in rows})} suites")
    for v in args.values:
        mine = [r for r in rows if r[args.setting] == v]
        faults = [r for r in mine if "ac1_strict" in r]
        mean = {k: sum(r[k] for r in faults) / len(faults) for k in FIELDS[-3:]} if faults else {}
        healthy = sum(r["alerts"] for r in mine if "ac1_strict" not in r)
        before = sum(r["before_injection"] for r in faults)
        print(f"{args.setting}={v}: {len(faults)} faults " + " ".join(f"{k}={x:.3f}" for k, x in mean.items())
              + f"; healthy alerts {healthy}; before injections {before}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
