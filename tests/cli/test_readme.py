"""The README stays true: its commands parse, its config example loads, its files exist."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from stream_viz.cli import build_parser
from stream_viz.config import load_config
from stream_viz.detect.plugin_set import PluginSet

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def commands() -> list[list[str]]:
    out = []
    for block in blocks("bash"):
        for line in block.splitlines():
            line = line.split("#")[0].strip()
            for part in line.split("&&"):
                words = shlex.split(part)
                if words and words[0].endswith("stream-viz"):
                    out.append(words[1:])
    return out


def test_readme_has_the_two_setup_commands_and_ci_runs_the_test_one():
    assert "bash scripts/install && .venv/bin/stream-viz demo" in README
    assert "bash scripts/test" in README
    assert "bash scripts/test" in (ROOT / ".ci" / "run").read_text()


@pytest.mark.parametrize("argv", commands(), ids=lambda a: " ".join(a)[:40])
def test_readme_commands_parse(argv):
    args = build_parser().parse_args(argv)
    assert callable(args.func)


def test_readme_config_example_is_valid(tmp_path):
    (toml,) = blocks("toml")
    path = tmp_path / "c.toml"
    path.write_text(toml)
    config = load_config(path)
    assert config.rca.policy == "both" and config.expected_rates == {"topic:/scan": 10.0}
    PluginSet.from_config(config).close()  # plugin settings are checked against the plugins


def test_readme_files_exist():
    for rel in re.findall(r"`((?:docs|scripts|bench|plugins|blueprints)/[\w./-]+)`", README):
        assert (ROOT / rel).exists(), rel
    assert (ROOT / "docs/img/demo.png").exists()
