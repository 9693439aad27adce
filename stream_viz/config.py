"""The TOML configuration: every key checked, every error naming the key and the file.

Sections: ``[monitor]``, ``[watchlist]``, ``[rca]``, ``[plugins]`` (+ ``[plugins.<name>]`` per
plugin, validated against the plugin's ``settings`` when the plugins load) and
``[topics."<topic name>"]``.
"""

from __future__ import annotations

import importlib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from stream_viz.detect.api import value_fits
from stream_viz.errors import ConfigError
from stream_viz.model.ids import make_id

WATCH_MODES = ("auto", "all", "config")


@dataclass(frozen=True)
class MonitorConfig:
    """``[monitor]``: sampling period (s), whether to measure topics, history length (samples),
    how long a vanished member stays in the model (s; 0 = the whole run), minutes per file part
    of a saved recording (0 = one file)."""

    period: float = 1.0
    topic_metrics: bool = True
    history: int = 600
    forget_gone_s: float = 600.0
    recording_part_minutes: float = 10.0


@dataclass(frozen=True)
class WatchlistConfig:
    """``[watchlist]``: how ``W_0`` is chosen and the members named by importance (patterns allowed)."""

    mode: str = "auto"
    members: tuple[str, ...] = ()


@dataclass(frozen=True)
class PluginsConfig:
    """``[plugins]``: which plugins run, extra plugin folders, and per-plugin settings."""

    enable: tuple[str, ...] = ()
    disable: tuple[str, ...] = ()
    paths: tuple[Path, ...] = ()
    settings: dict[str, dict[str, Any]] = field(default_factory=dict)


@dataclass(frozen=True)
class Config:
    """The whole configuration; ``path`` is None for the defaults."""

    path: Path | None = None
    monitor: MonitorConfig = field(default_factory=MonitorConfig)
    watchlist: WatchlistConfig = field(default_factory=WatchlistConfig)
    rca: Any = field(default_factory=dict)
    plugins: PluginsConfig = field(default_factory=PluginsConfig)
    topics: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def expected_rates(self) -> dict[str, float]:
        """Topic member id to the expected rate in Hz."""
        return {t: v["expected_rate_hz"] for t, v in self.topics.items() if "expected_rate_hz" in v}


_MONITOR = {"period": 1.0, "topic_metrics": True, "history": 600, "forget_gone_s": 600.0,
            "recording_part_minutes": 10.0}
_WATCHLIST = {"mode": "auto", "members": [""]}
_PLUGINS = {"enable": [""], "disable": [""], "paths": [""]}
_TOPIC = {"expected_rate_hz": 1.0}


def _table(where: str, section: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: [{section}] must be a table, not {type(value).__name__}")
    return value


def _check(where: str, section: str, table: dict[str, Any], spec: dict[str, Any]) -> dict[str, Any]:
    """Check keys and types of ``table`` against ``spec`` (a default per key; lists give the item type)."""
    out = {}
    for key, value in table.items():
        if key not in spec:
            raise ConfigError(f"{where}: [{section}] unknown key {key!r} (known: {', '.join(sorted(spec))})")
        default = spec[key]
        if not value_fits(default, value):
            raise ConfigError(f"{where}: [{section}] {key} must be {type(default).__name__}, "
                              f"not {type(value).__name__} ({value!r})")
        if isinstance(default, list):
            for item in value:
                if not value_fits(default[0], item):
                    raise ConfigError(f"{where}: [{section}] {key}: items must be "
                                      f"{type(default[0]).__name__}, not {item!r}")
            value = tuple(value)
        elif isinstance(default, float):
            value = float(value)
        out[key] = value
    return out


def _rca(where: str, raw: dict[str, Any]) -> Any:
    try:
        mod = importlib.import_module("stream_viz.rca.settings")
    except ImportError:
        return dict(raw)
    return mod.RcaSettings.from_dict(raw, where)


def load_config(path: str | Path | None) -> Config:
    """Read and check a TOML configuration; ``None`` gives the defaults.

    Raises
    ------
    ConfigError
        The file is unreadable or malformed, or a section/key is unknown or of the wrong type.
    """
    if path is None:
        return Config(rca=_rca("defaults", {}))
    path = Path(path)
    where = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{where}: cannot read the configuration: {exc}") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: malformed TOML: {exc}") from exc

    known = ("monitor", "watchlist", "rca", "plugins", "topics")
    for section in data:
        if section not in known:
            raise ConfigError(f"{where}: unknown section [{section}] (known: {', '.join(known)})")

    monitor = _check(where, "monitor", _table(where, "monitor", data.get("monitor", {})), _MONITOR)
    if monitor.get("period", 1.0) <= 0:
        raise ConfigError(f"{where}: [monitor] period must be > 0, not {monitor['period']}")
    if monitor.get("history", 600) < 2:
        raise ConfigError(f"{where}: [monitor] history must be >= 2 samples, not {monitor['history']}")

    if monitor.get("recording_part_minutes", 10.0) < 0:
        raise ConfigError(f"{where}: [monitor] recording_part_minutes must be >= 0 (0: one file), "
                          f"not {monitor['recording_part_minutes']}")

    watch = _check(where, "watchlist", _table(where, "watchlist", data.get("watchlist", {})), _WATCHLIST)
    if watch.get("mode", "auto") not in WATCH_MODES:
        raise ConfigError(f"{where}: [watchlist] mode must be one of {', '.join(WATCH_MODES)}, "
                          f"not {watch['mode']!r}")

    rca = _rca(where, _table(where, "rca", data.get("rca", {})))

    plugins_raw = dict(_table(where, "plugins", data.get("plugins", {})))
    per_plugin = {k: v for k, v in plugins_raw.items() if isinstance(v, dict)}
    top = {k: v for k, v in plugins_raw.items() if k not in per_plugin}
    plugins = _check(where, "plugins", top, _PLUGINS)
    plugins["paths"] = tuple((path.parent / p).resolve() for p in plugins.get("paths", ()))
    plugins["settings"] = {name: dict(v) for name, v in per_plugin.items()}

    topics: dict[str, dict[str, float]] = {}
    for name, table in _table(where, "topics", data.get("topics", {})).items():
        section = f'topics."{name}"'
        try:
            tid = make_id("topic", name)
        except Exception as exc:
            raise ConfigError(f"{where}: [{section}]: {exc}") from exc
        checked = _check(where, section, _table(where, section, table), _TOPIC)
        rate = checked.get("expected_rate_hz")
        if rate is not None and rate <= 0:
            raise ConfigError(f"{where}: [{section}] expected_rate_hz must be > 0, not {rate}")
        topics[tid] = checked

    return Config(
        path=path,
        monitor=MonitorConfig(**monitor),
        watchlist=WatchlistConfig(**watch),
        rca=rca,
        plugins=PluginsConfig(**plugins),
        topics=topics,
    )
