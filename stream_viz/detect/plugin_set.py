"""The plugins of one run and the policy around them: which run, with which settings, and when
one that keeps failing is switched off.

`PluginSet.load` discovers the plugins (`stream_viz.detect.discovery`), applies the config's
``enable``/``disable`` and settings; `PluginSet.run` calls every enabled plugin on one sample,
each isolated (`stream_viz.detect.isolation`), and disables one after ``max_failures`` failed
calls in a row.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import networkx as nx

from stream_viz.detect.api import Plugin, PluginContext, members_by_kind, watched_by_kind
from stream_viz.detect.discovery import discover
from stream_viz.detect.isolation import Runner, screen
from stream_viz.detect.problems import PluginProblem
from stream_viz.errors import ConfigError
from stream_viz.model.diff import GraphDiff
from stream_viz.model.history import History
from stream_viz.records import Alert, Event
from stream_viz.settings import check_plugin_settings

# A member that left the graph this recently may still be named by an alert: a plugin that waits
# to be sure (a process that ended alone) speaks of it after it left.
LEFT_KNOWN_S = 60.0


@dataclass
class LoadedPlugin:
    """A validated plugin with its settings, private state, runner and health."""

    name: str
    plugin: Plugin
    where: str
    settings: dict[str, Any]
    runner: Runner
    state: dict[str, Any] = field(default_factory=dict)
    learned: dict[str, Any] = field(default_factory=dict)  # carried across runs (`learned`)
    # What it started from (`prime`), read-only: ``ctx.primed``.
    primed: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    failures: int = 0
    disabled: bool = False


class PluginSet:
    """The plugins of one run, each called in isolation on every sample.

    Parameters
    ----------
    plugins : list of (instance, name, where)
        As `discover` returns them.
    settings : mapping
        Plugin name to setting overrides (validated here).
    timeout_s : float
        Longest one call may take before it is cut off.
    max_alerts_per_call : int
        More alerts from one call are dropped (counted, reported).
    max_failures : int
        A plugin failing (raising, timing out) this many calls in a row is disabled.
    isolate : bool
        Run each call in the plugin's own worker thread with a deadline (False: inline, only
        for benchmarks and debugging).
    config_path : str, optional
        The file the settings came from, named in errors.
    load_problems : list of PluginProblem
        What went wrong while loading (kept in ``load_problems``).
    """

    def __init__(
        self,
        plugins: Sequence[tuple[Plugin, str, str]],
        settings: Mapping[str, Mapping[str, Any]] | None = None,
        *,
        timeout_s: float = 0.5,
        max_alerts_per_call: int = 200,
        max_failures: int = 3,
        isolate: bool = True,
        config_path: str | None = None,
        load_problems: Sequence[PluginProblem] = (),
    ) -> None:
        self.max_alerts_per_call = max_alerts_per_call
        self._left: dict[str, float] = {}  # member -> when it left the graph (`LEFT_KNOWN_S`)
        self.max_failures = max_failures
        self.load_problems = list(load_problems)
        self.plugins: list[LoadedPlugin] = []
        self._settings: dict[str, dict[str, Any]] = {}  # of every plugin found, switched off too
        settings = dict(settings or {})
        where_cfg = config_path or "the configuration"
        for inst, name, where in plugins:
            merged = check_plugin_settings(type(inst).settings, settings.get(name, {}), where_cfg,
                                           f"plugins.{name}")
            runner = Runner(inst, name, where, timeout_s=timeout_s, limit=max_alerts_per_call,
                            isolate=isolate)
            self.plugins.append(LoadedPlugin(name, inst, where, merged, runner))
            self._settings[name] = merged

    @classmethod
    def load(
        cls,
        folders: Sequence[str | Path] = (),
        *,
        enable: Sequence[str] = (),
        disable: Sequence[str] = (),
        settings: Mapping[str, Mapping[str, Any]] | None = None,
        entry_points: bool = True,
        cwd_plugins: bool = True,
        config_path: str | None = None,
        **kwargs: Any,
    ) -> PluginSet:
        """Discover plugins, apply ``enable``/``disable`` and settings, and return the set.

        Raises
        ------
        ConfigError
            A setting is unknown or of the wrong type, or settings name a plugin that does
            not exist (and did not fail to load).
        """
        found, problems, failed = discover(folders, entry_points=entry_points, cwd_plugins=cwd_plugins)
        names = {n for _, n, _ in found}
        where_cfg = config_path or "the configuration"
        for name in settings or {}:
            if name not in names and name not in failed:
                raise ConfigError(f"{where_cfg}: [plugins.{name}]: no plugin named {name!r} "
                                  f"(known: {', '.join(sorted(names))})")
        for key, listed in (("enable", enable), ("disable", disable)):
            for name in listed:
                if name not in names and name not in failed:
                    problems.append(PluginProblem(name, where_cfg, "config",
                                                  f"[plugins] {key} names an unknown plugin"))
        keep = [p for p in found if (not enable or p[1] in enable) and p[1] not in disable]
        settings = {k: v for k, v in (settings or {}).items() if k in names}
        # Validate settings of plugins switched off too, so a typo never hides.
        every = cls(found, settings, config_path=config_path)
        kept = cls(keep, settings, config_path=config_path, load_problems=problems, **kwargs)
        kept._settings = every._settings | kept._settings
        return kept

    @classmethod
    def from_config(cls, config: Any, **kwargs: Any) -> PluginSet:
        """Build the set from a `stream_viz.config.Config`."""
        p = config.plugins
        return cls.load(p.paths, enable=p.enable, disable=p.disable, settings=p.settings,
                        config_path=str(config.path) if config.path else None, **kwargs)

    def settings_of(self, name: str) -> dict[str, Any] | None:
        """Return the settings (defaults and configured values) of the plugin ``name``, also when
        it is switched off; None when no such plugin was found.

        The monitor reads ``process_resources``'s: they also tune the process evidence
        (`stream_viz.detect.process.process_anomalies`).
        """
        return self._settings.get(name)

    @property
    def names(self) -> list[str]:
        """Names of the plugins that still run."""
        return [p.name for p in self.plugins if not p.disabled]

    def run(
        self,
        t: float,
        graph: nx.MultiDiGraph,
        watch: Iterable[str],
        history: History,
        events: Sequence[Event] = (),
        diff: GraphDiff | None = None,
        expected_rates: Mapping[str, float] | None = None,
    ) -> tuple[list[Alert], list[PluginProblem]]:
        """Call every enabled plugin on one sample.

        Returns
        -------
        alerts : list of Alert
            Valid alerts, plugin by plugin, each plugin's in its own order.
        problems : list of PluginProblem
            What went wrong during this call.
        """
        diff = diff or GraphDiff()
        watch = frozenset(watch)
        events = list(events)
        rates = dict(expected_rates or {})
        self._left = {m: t0 for m, t0 in self._left.items() if t - t0 <= LEFT_KNOWN_S and m not in graph}
        self._left.update(dict.fromkeys(diff.removed_members, t))
        known = set(graph.nodes) | set(self._left) | {e.member for e in events}
        by_kind, of_kind = watched_by_kind(graph, watch), members_by_kind(graph)
        alerts: list[Alert] = []
        problems: list[PluginProblem] = []
        for lp in self.plugins:
            if lp.disabled:
                continue
            ctx = PluginContext(t, graph, watch, history, events, diff, lp.settings, lp.state,
                                learned=lp.learned, primed=lp.primed, expected_rates=rates, plugin=lp.name,
                                kinds=tuple(lp.plugin.kinds), by_kind=by_kind, of_kind=of_kind)
            items, more, problem = lp.runner.call(ctx)
            if problem is not None:
                problems += self._failed(lp, problem)
                continue
            lp.failures = 0
            good, bad = screen(lp.name, lp.where, items, more, known, self.max_alerts_per_call, t)
            problems += bad
            alerts += good
        return alerts, problems

    def learned(self, t: float | None = None) -> tuple[dict[str, dict[str, Any]], list[PluginProblem]]:
        """Return what each plugin learned to carry to later runs (``ctx.learned``, the non-empty
        ones), and a problem for each whose values are not JSON (left out, the others kept)."""
        out: dict[str, dict[str, Any]] = {}
        problems: list[PluginProblem] = []
        for lp in self.plugins:
            if not lp.learned:
                continue
            try:
                out[lp.name] = json.loads(json.dumps(lp.learned))
            except (TypeError, ValueError) as exc:
                problems.append(PluginProblem(lp.name, lp.where, "garbage",
                                              f"what it learned is not JSON, not kept: {exc}", t=t))
        return out, problems

    def primed_by(self, name: str) -> Mapping[str, Any]:
        """What plugin ``name`` started from (`prime`; empty when it is not loaded or was not
        primed): the process rule's evidence reads the bursts ``process_resources`` carried."""
        return next((lp.primed for lp in self.plugins if lp.name == name), {})

    def prime(self, learned: Mapping[str, Any]) -> list[str]:
        """Start each plugin from what it learned in an earlier run (`learned`); return the names
        of those primed. A plugin's entry that is not a mapping is left out."""
        primed = []
        for lp in self.plugins:
            mine = learned.get(lp.name)
            if isinstance(mine, Mapping) and mine:
                lp.learned = copy.deepcopy(dict(mine))
                lp.primed = MappingProxyType(copy.deepcopy(dict(mine)))
                primed.append(lp.name)
        return primed

    def _failed(self, lp: LoadedPlugin, problem: PluginProblem) -> list[PluginProblem]:
        """Count a failed call; disable the plugin after ``max_failures`` in a row."""
        lp.failures += 1
        if lp.failures < self.max_failures:
            return [problem]
        lp.disabled = True
        lp.runner.stop()  # a hung thread is abandoned; it ends when its call does
        return [problem, PluginProblem(lp.name, lp.where, "disabled",
                                       f"disabled after {lp.failures} failed calls in a row", t=problem.t)]

    def timings(self) -> dict[str, tuple[int, float]]:
        """Plugin name to ``(calls, total seconds)``."""
        return {p.name: (p.runner.calls, p.runner.seconds) for p in self.plugins}

    def close(self) -> None:
        """Stop the worker threads (hung ones are left to end on their own)."""
        for lp in self.plugins:
            lp.runner.stop()
