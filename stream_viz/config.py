"""The TOML configuration: every table checked by the one settings mechanism (`stream_viz.settings`).

Sections: ``[monitor]``, ``[watchlist]``, ``[rca]``, ``[plugins]`` (+ ``[plugins.<name>]`` per
plugin, checked against the plugin's ``settings`` when the plugins load) and
``[topics."<topic name>"]``. Each becomes a frozen settings object; an error names the file, the
section, the key, the value and what was expected.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stream_viz.errors import ConfigError
from stream_viz.model.ids import make_id
from stream_viz.rca.settings import RcaSettings
from stream_viz.settings import expect_table, load, not_a_key, setting, toml_key, unknown_key

WATCH_MODES = ("auto", "all", "config")


@dataclass(frozen=True)
class MonitorConfig:
    """``[monitor]``: sampling period (s), whether to measure topics, history length (samples),
    how long a vanished member stays in the model (s; <= 0: the whole run), minutes per file part
    of a saved recording (0 = one file), whether the viewer gets the condensed system graph
    (``auto``: above ``condense_above`` members; ``on``; ``off``)."""

    period: float = setting(1.0, gt=0)
    topic_metrics: bool = True
    history: int = setting(600, ge=2)
    forget_gone_s: float = 600.0
    recording_part_minutes: float = setting(10.0, ge=0)
    condensed: str = setting("auto", choices=("auto", "on", "off"))
    condense_above: int = setting(300, ge=0)


@dataclass(frozen=True)
class WatchlistConfig:
    """``[watchlist]``: how ``W_0`` is chosen and the members named by importance (patterns allowed)."""

    mode: str = setting("auto", choices=WATCH_MODES)
    members: tuple[str, ...] = ()


@dataclass(frozen=True)
class PluginsConfig:
    """``[plugins]``: which plugins run, extra plugin folders (relative to the file), and the
    per-plugin ``[plugins.<name>]`` tables (checked when the plugins load)."""

    enable: tuple[str, ...] = ()
    disable: tuple[str, ...] = ()
    paths: tuple[Path, ...] = ()
    settings: dict[str, dict[str, Any]] = not_a_key(dict)


@dataclass(frozen=True)
class TopicConfig:
    """``[topics."<name>"]``: what the configuration expects of one topic."""

    expected_rate_hz: float | None = setting(None, gt=0)


@dataclass(frozen=True)
class Config:
    """The whole configuration; ``path`` is None for the defaults."""

    path: Path | None = None
    monitor: MonitorConfig = field(default_factory=MonitorConfig)
    watchlist: WatchlistConfig = field(default_factory=WatchlistConfig)
    rca: RcaSettings = field(default_factory=RcaSettings)
    plugins: PluginsConfig = field(default_factory=PluginsConfig)
    topics: dict[str, TopicConfig] = field(default_factory=dict)

    @property
    def expected_rates(self) -> dict[str, float]:
        """Topic member id to the expected rate in Hz."""
        return {t: v.expected_rate_hz for t, v in self.topics.items() if v.expected_rate_hz is not None}


SECTIONS = ("monitor", "watchlist", "rca", "plugins", "topics")


def load_config(path: str | Path | None, text: str | None = None) -> Config:
    """Read and check a TOML configuration; ``None`` gives the defaults.

    ``text``, when given, is the file's content (a replay: the configuration its run recorded);
    ``path`` still names it and anchors its relative plugin paths.

    Raises
    ------
    ConfigError
        The file is unreadable or malformed, or a section/key is unknown or its value is bad.
    """
    if path is None:
        return Config()
    path = Path(path)
    where = str(path)
    try:
        text = path.read_text(encoding="utf-8") if text is None else text
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{where}: cannot read the configuration: {exc}") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: malformed TOML: {exc}") from exc
    for section in data:
        if section not in SECTIONS:
            raise unknown_key(where, "", section, SECTIONS)

    # [plugins] holds its own keys and one sub-table per plugin.
    plugins_raw = expect_table(data.get("plugins", {}), where, "plugins")
    per_plugin = {k: v for k, v in plugins_raw.items() if isinstance(v, dict)}
    plugins = load(PluginsConfig, {k: v for k, v in plugins_raw.items() if k not in per_plugin},
                   where, "plugins")
    topics = {}
    for name, table in expect_table(data.get("topics", {}), where, "topics").items():
        section = f"topics.{toml_key(name)}"
        try:
            tid = make_id("topic", name)
        except Exception as exc:
            raise ConfigError(f"{where}: [{section}]: {exc}") from exc
        topics[tid] = load(TopicConfig, table, where, section)
    return Config(
        path=path,
        monitor=load(MonitorConfig, data.get("monitor", {}), where, "monitor"),
        watchlist=load(WatchlistConfig, data.get("watchlist", {}), where, "watchlist"),
        rca=load(RcaSettings, data.get("rca", {}), where, "rca"),
        plugins=PluginsConfig(
            enable=plugins.enable,
            disable=plugins.disable,
            paths=tuple((path.parent / p).resolve() for p in plugins.paths),
            settings={name: dict(v) for name, v in per_plugin.items()},
        ),
        topics=topics,
    )
