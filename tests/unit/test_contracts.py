"""docs/contracts.md stays true: it names every entity path, command option and database table
the code has, and the versions the code writes."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from stream_viz.cli import build_parser
from stream_viz.collect.samples_file import FORMAT
from stream_viz.detect.store import MIGRATIONS, SCHEMA_VERSION
from stream_viz.report import SCHEMA
from stream_viz.viz import paths

CONTRACTS = (Path(__file__).resolve().parents[2] / "docs" / "contracts.md").read_text()


def subcommands() -> dict[str, argparse.ArgumentParser]:
    (action,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def test_every_entity_path_and_timeline_is_named():
    for value in (paths.SYSTEM, paths.PROCESS_TREE, paths.ALERTS, paths.CHANGES, paths.RCA_SUBGRAPH,
                  paths.RCA_TRAJECTORY,
                  paths.RCA_REPORT, paths.TIME, paths.RCA_ITERATION):
        assert f"`{value}`" in CONTRACTS, value
    assert f"`{paths.HEALTH}/<kind>/<name>`" in CONTRACTS
    assert paths.health_path("topic:/camera/image") == "/health/topic/camera/image"
    for leaf in (paths.THETA, paths.ALERT_MARKERS):
        assert f"`{paths.METRICS}/<kind>/<name>/{leaf}`" in CONTRACTS, leaf
    assert "`/metrics/topic/camera/image/theta`" in CONTRACTS
    for root in paths.GROUP_ROOTS:
        assert f"`{root}/" in CONTRACTS, root
    assert paths.group_path("namespace", "/amr1") == "/namespace/amr1"
    assert "`/namespace/amr1`" in CONTRACTS
    assert paths.metrics_path("topic:/camera/image", paths.THETA) == "/metrics/topic/camera/image/theta"


@pytest.mark.parametrize("command", sorted(subcommands()))
def test_every_command_and_option_is_named(command):
    assert f"| `{command}` |" in CONTRACTS
    for action in subcommands()[command]._actions:
        for option in action.option_strings:
            if option.startswith("--") and option != "--help":
                assert f"`{option}" in CONTRACTS, f"{command} {option}"


def test_every_table_and_the_versions_are_named():
    tables = {m.group(1) for stmts in MIGRATIONS for s in stmts
              for m in [re.match(r"CREATE TABLE (\w+)", s)] if m}
    assert tables == {"meta", "runs", "alerts", "snapshots", "problems", "episodes"}
    for table in tables:
        assert f"| `{table}` |" in CONTRACTS, table
    assert f"**Schema version {SCHEMA_VERSION}**" in CONTRACTS
    assert f"`{SCHEMA}`" in CONTRACTS
    assert f"`{FORMAT}`" in CONTRACTS
