"""``stream-viz analyze``: rerun the root-cause analysis offline on a saved alert database."""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path
from typing import Any

NAME = "analyze"
HELP = "rerun the root-cause analysis offline on a saved alert database"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--db", type=Path, required=True, metavar="FILE.sqlite")
    p.add_argument("--policy", choices=("downstream", "upstream", "both"))
    p.add_argument("--method", help="correlation method (see docs/rca.md)")
    p.add_argument("--config", type=Path, metavar="FILE.toml")
    p.add_argument("--report", type=Path, metavar="FILE.json")
    p.add_argument("--save", type=Path, metavar="FILE.rrd", help="write the diagnosis as a recording")


def run(args: argparse.Namespace) -> int:
    """Read the model snapshot and alerts from ``--db``, rank root causes, print and write them."""
    from stream_viz.output import check_writable
    from stream_viz.rca.engine import analyze
    from stream_viz.report import build_report, write_report

    settings = _rca_settings(args)
    if args.report:
        check_writable(args.report, "report")
    if args.save:
        check_writable(args.save, "recording")
    G, alerts, watch, started, ended, injected, problems, limits = read_run(args.db)
    result = analyze(G, alerts, settings, set(watch) if watch else None)
    report = build_report(G, alerts, result.to_report(), started, ended, injected, problems, limits)
    for rank, rc in enumerate(report["root_causes"][:10], 1):
        print(f"{rank}. {rc['member']}  score {rc['score']:.2f}  trajectory: {' <- '.join(rc['trajectory'])}")
    if args.report:
        write_report(args.report, report)
        print(f"report: {args.report}")
    if args.save:
        from stream_viz.viz.live import save_diagnosis

        save_diagnosis(args.save, G, alerts, result)
        print(f"recording: {args.save}")
    if not args.report and not report["root_causes"]:
        print(json.dumps({"root_causes": []}))
    return 0


def _rca_settings(args: argparse.Namespace) -> Any:
    """The configuration's RCA settings with ``--policy`` and ``--method`` applied (checked)."""
    from stream_viz.config import load_config

    settings = load_config(args.config).rca
    overrides = {k: v for k, v in (("policy", args.policy), ("method", args.method)) if v}
    if overrides:
        settings = dataclasses.replace(settings, **overrides)
        settings = type(settings).from_dict(dataclasses.asdict(settings), "command line")
    return settings


def read_run(db: Path) -> tuple[Any, list[Any], Any, float, float, Any, list[dict[str, Any]], dict[str, str]]:
    """The model, alerts, saved watchlist, start, end, injected fault, problems and collector limits
    of the run in ``db``."""
    from stream_viz.detect.store import AlertStore
    from stream_viz.errors import StoreError

    store = AlertStore(db, readonly=True)
    try:
        G = store.latest_snapshot()
        alerts = store.alerts()
        watch = store.get_meta("watchlist")
        started = store.get_meta("started_at") or (alerts[0].t if alerts else time.time())
        ended = store.get_meta("ended_at") or (alerts[-1].t if alerts else started)
        injected = store.get_meta("injected")
        problems = store.problems()
        limits = store.get_meta("collector_limits") or {}
    finally:
        store.close()
    if G is None:
        raise StoreError(f"{db}: holds no model snapshot (was it written by stream-viz monitor?)")
    if not alerts:
        raise StoreError(f"{db}: holds no alerts, nothing to analyse")
    return G, alerts, watch, started, ended, injected, problems, limits
