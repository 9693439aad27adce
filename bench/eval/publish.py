"""A suite's results as small files for the repository: ``<results>/<suite>-<commit>/``.

From what `bench.eval.run.report` wrote into the suite's output folder: ``results.md`` and
``scores.csv`` as they are, ``summary.json`` without its score rows (``scores.csv`` has them),
``runs.jsonl`` trimmed (rankings and peers' rankings to their first `KEEP` items, alert messages
shortened), and ``about.json``: the suite, the command, the code (commits) and the machine.
Not the alert databases, not the metric tables (``bench/out/<suite>/`` keeps those).
"""

from __future__ import annotations

import json
import shutil
import time
from collections import Counter
from pathlib import Path

KEEP = 10  # ranked items kept per ranking: AC@1..5 need the first 5 nodes; scores.csv has the rest
MESSAGE = 120  # characters of an alert message kept


def publish(out: Path, suite: str, root: Path, argv: list[str]) -> Path:
    """Write the small result files of the suite in ``out`` to ``root/<suite>-<commit>/``; return it."""
    runs = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines() if line.strip()]
    about = provenance(runs, suite, argv)
    dest = root / f"{suite}-{about['folder_commit']}"
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("results.md", "scores.csv"):
        if (out / name).exists():
            shutil.copyfile(out / name, dest / name)
    summary = json.loads((out / "summary.json").read_text())
    (dest / "summary.json").write_text(json.dumps({k: v for k, v in summary.items() if k != "rows"}) + "\n")
    with open(dest / "runs.jsonl", "w") as f:
        for run in runs:
            f.write(json.dumps(trim(run)) + "\n")
    (dest / "about.json").write_text(json.dumps(about, indent=1) + "\n")
    return dest


def trim(run: dict) -> dict:
    """A line of ``runs.jsonl`` made small: rankings cut to `KEEP`, no peers' extras, short messages."""
    out = dict(run)
    out["rankings"] = {k: v[:KEEP] if isinstance(v, list) else v for k, v in run.get("rankings", {}).items()}
    peers = run.get("peers")
    if isinstance(peers, dict):
        out["peers"] = {
            name: ({k: (v[:KEEP] if k == "ranking" else v) for k, v in res.items()
                    if k not in ("columns", "trace")} if isinstance(res, dict) else res)
            for name, res in peers.items()
        }
    out["alerts"] = [{**a, "message": a.get("message", "")[:MESSAGE]} for a in run.get("alerts", [])]
    return out


def provenance(runs: list[dict], suite: str, argv: list[str]) -> dict:
    """What ran on what: commits (with counts and uncommitted changes), machines, times, load."""
    codes = [r.get("code") or {} for r in runs]
    commits = Counter(c.get("commit") or "unknown" for c in codes)
    dirty = sorted({c.get("commit") or "unknown" for c in codes if c.get("dirty")})
    main = commits.most_common(1)[0][0] if commits else "unknown"
    machines = [json.loads(m) for m in sorted({json.dumps(r.get("machine"), sort_keys=True) for r in runs})]
    starts = [r["t_start"] for r in runs if "t_start" in r]
    loads = [r["loadavg"][0] for r in runs if r.get("loadavg")]
    return {
        "suite": suite,
        "command": "python -m bench.eval.run " + " ".join(argv),
        "runs": len(runs),
        "commits": dict(commits),
        "dirty": dirty,  # commits some runs measured with uncommitted changes on top
        "folder_commit": main[:7] + ("-dirty" if main in dirty else ""),
        "machines": machines,
        "first_run": _utc(min(starts)) if starts else None,
        "last_run": _utc(max(starts)) if starts else None,
        "load_1min": [min(loads), max(loads)] if loads else None,
    }


def _utc(t: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%MZ", time.gmtime(t))
