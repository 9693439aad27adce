"""Finding, validating and running symptom plugins, each in isolation.

Plugins come from the entry-point group ``stream_viz.plugins`` (the built-ins are registered
there exactly like a user's) and from plugin folders (those the config names, then ``./plugins``).
Whatever one plugin does — fail to import, fail validation, raise, hang, return garbage, flood —
is reported as a `PluginProblem` naming it and where, and the others and the caller go on.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import importlib.util
import inspect
import itertools
import math
import queue
import re
import sys
import threading
import time
import traceback
import types
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import networkx as nx

from stream_viz.detect.api import API_VERSION, Plugin, PluginContext, watched_by_kind
from stream_viz.errors import ConfigError
from stream_viz.model.diff import GraphDiff
from stream_viz.model.history import History
from stream_viz.model.ids import KINDS
from stream_viz.records import SEVERITIES, Alert, Event
from stream_viz.settings import check_plugin_settings

GROUP = "stream_viz.plugins"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")
_SETTING_TYPES = (bool, int, float, str, list, tuple, type(None))


@dataclass(frozen=True)
class PluginProblem:
    """Something wrong with one plugin: which, where, what and the line that failed.

    ``kind`` is one of ``import``, ``validate``, ``duplicate``, ``config``, ``run``, ``timeout``,
    ``garbage``, ``flood``, ``disabled``.
    """

    plugin: str
    where: str
    kind: str
    message: str
    line: str = ""
    t: float | None = None
    count: int = 0

    def __str__(self) -> str:
        at = f" at {self.line}" if self.line else ""
        return f"plugin {self.plugin!r} ({self.where}): {self.kind}: {self.message}{at}"


def _failing_line(exc: BaseException) -> str:
    """Return ``file:line in func`` of the innermost frame that is not import machinery."""
    if isinstance(exc, SyntaxError) and exc.filename:
        return f"{exc.filename}:{exc.lineno}"
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith("<frozen")]
    if not frames:
        return ""
    f = frames[-1]
    return f"{f.filename}:{f.lineno} in {f.name}"


def _describe(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


@dataclass
class _Call:
    ctx: PluginContext
    limit: int
    done: threading.Event = field(default_factory=threading.Event)
    result: list[Any] = field(default_factory=list)
    more: bool = False
    error: BaseException | None = None


class _Worker:
    """One daemon thread per plugin; a hung call can be abandoned (the thread is never joined)."""

    def __init__(self, plugin: Plugin, name: str) -> None:
        self._plugin = plugin
        self._q: queue.SimpleQueue[_Call | None] = queue.SimpleQueue()
        self.current: _Call | None = None
        threading.Thread(target=self._loop, name=f"stream-viz-plugin-{name}", daemon=True).start()

    def _loop(self) -> None:
        while (call := self._q.get()) is not None:
            _execute(self._plugin, call)

    @property
    def busy(self) -> bool:
        return self.current is not None and not self.current.done.is_set()

    def submit(self, call: _Call) -> None:
        self.current = call
        self._q.put(call)

    def stop(self) -> None:
        self._q.put(None)


def _execute(plugin: Plugin, call: _Call) -> None:
    try:
        out = plugin.check(call.ctx)
        if out is None:
            out = ()
        if isinstance(out, list | tuple):
            call.result = list(out)
        else:
            # A generator could be endless: count up to 10x the limit, then note there was more.
            cap = 10 * call.limit
            items = list(itertools.islice(iter(out), cap + 1))
            call.more = len(items) > cap
            call.result = items[:cap]
    except BaseException as exc:
        call.error = exc
    finally:
        call.done.set()


@dataclass
class LoadedPlugin:
    """A validated plugin with its settings, private state and health."""

    name: str
    plugin: Plugin
    where: str
    settings: dict[str, Any]
    state: dict[str, Any] = field(default_factory=dict)
    failures: int = 0
    disabled: bool = False
    calls: int = 0
    seconds: float = 0.0
    worker: _Worker | None = None


# --------------------------------------------------------------------------- discovery

def _candidates(obj: Any, module: types.ModuleType | None) -> list[Any]:
    """Plugin classes/instances an entry-point target or a folder module offers."""
    if isinstance(obj, types.ModuleType):
        if hasattr(obj, "PLUGINS"):
            return list(obj.PLUGINS)
        return [
            c for _, c in sorted(vars(obj).items())
            if inspect.isclass(c) and issubclass(c, Plugin) and c is not Plugin
            and c.__module__ == obj.__name__ and not c.__name__.startswith("_")
        ]
    if isinstance(obj, list | tuple):
        return list(obj)
    return [obj]


def _where_of(obj: Any, fallback: str) -> str:
    cls = obj if inspect.isclass(obj) else type(obj)
    try:
        return f"{inspect.getsourcefile(cls) or fallback}"
    except TypeError:
        return fallback


def _validate(obj: Any, where: str) -> tuple[Plugin | None, str, PluginProblem | None]:
    """Return ``(instance, name, None)`` or ``(None, name, problem)``."""
    cls = obj if inspect.isclass(obj) else type(obj)
    name = getattr(cls, "name", None)
    shown = name if isinstance(name, str) and name else getattr(cls, "__name__", repr(obj))

    def bad(msg: str, line: str = "") -> tuple[None, str, PluginProblem]:
        return None, shown, PluginProblem(shown, where, "validate", msg, line)

    if not (inspect.isclass(cls) and issubclass(cls, Plugin)):
        return bad(f"{obj!r} is not a stream_viz.detect.api.Plugin subclass")
    if not isinstance(name, str) or not _NAME.match(name):
        return bad(f"class {cls.__name__}: name must be a word such as 'my_plugin', not {name!r}")
    if cls.api_version != API_VERSION:
        return bad(f"written for plugin API {cls.api_version!r}; this stream-viz speaks {API_VERSION}")
    kinds = cls.kinds
    if not isinstance(kinds, tuple | list) or not kinds or any(k not in KINDS for k in kinds):
        return bad(f"kinds must be a non-empty tuple of {KINDS}, not {kinds!r}")
    if not isinstance(cls.settings, dict) or any(not isinstance(k, str) for k in cls.settings):
        return bad(f"settings must be a dict with str keys, not {cls.settings!r}")
    for key, value in cls.settings.items():
        if not isinstance(value, _SETTING_TYPES):
            return bad(f"setting {key!r}: default {value!r} is not bool/int/float/str/list/None")
    if cls.check is Plugin.check:
        return bad("does not implement check(ctx)")
    if inspect.isclass(obj):
        try:
            obj = obj()
        except Exception as exc:
            return bad(f"could not be created: {_describe(exc)}", _failing_line(exc))
    return obj, name, None


def _import_folder_module(path: Path) -> types.ModuleType:
    tag = hashlib.sha1(str(path.parent).encode()).hexdigest()[:10]
    mod_name = f"stream_viz_folder_plugins_{tag}.{path.stem}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(mod_name, None)
        raise
    return module


def discover(
    folders: Sequence[str | Path] = (),
    *,
    entry_points: bool = True,
    cwd_plugins: bool = True,
) -> tuple[list[tuple[Plugin, str, str]], list[PluginProblem], set[str]]:
    """Find and validate plugins.

    Parameters
    ----------
    folders : sequence of path
        Plugin folders to scan (``*.py``, not starting with ``_``), in order.
    entry_points : bool
        Load the entry-point group ``stream_viz.plugins`` first.
    cwd_plugins : bool
        Also scan ``./plugins`` when it exists.

    Returns
    -------
    plugins : list of (instance, name, where)
        Valid plugins; on a name given twice the first wins.
    problems : list of PluginProblem
        One per plugin that failed to import or validate, or was a duplicate.
    failed : set of str
        Names (entry-point names, module stems, plugin names) of what failed to load.
    """
    found: list[tuple[Plugin, str, str]] = []
    problems: list[PluginProblem] = []
    failed: set[str] = set()
    seen_files: set[Path] = set()

    def add(objs: Iterable[Any], fallback_where: str) -> None:
        for obj in objs:
            where = _where_of(obj, fallback_where)
            inst, name, problem = _validate(obj, where)
            if problem is not None:
                problems.append(problem)
                failed.add(name)
                continue
            first = next((w for _, n, w in found if n == name), None)
            if first is not None:
                problems.append(PluginProblem(name, where, "duplicate",
                                              f"name already taken by the plugin from {first}; ignored"))
                continue
            found.append((inst, name, where))

    if entry_points:
        for ep in sorted(importlib.metadata.entry_points(group=GROUP), key=lambda e: e.name):
            try:
                obj = ep.load()
            except Exception as exc:
                problems.append(PluginProblem(ep.name, f"entry point {ep.value}", "import",
                                              _describe(exc), _failing_line(exc)))
                failed.add(ep.name)
                continue
            module = inspect.getmodule(obj)
            if module is not None and getattr(module, "__file__", None):
                seen_files.add(Path(module.__file__).resolve())
            add(_candidates(obj, module), f"entry point {ep.value}")

    dirs = [Path(f) for f in folders]
    local = Path.cwd() / "plugins"
    if cwd_plugins and local.is_dir() and all(local.resolve() != d.resolve() for d in dirs):
        dirs.append(local)
    for folder in dirs:
        if not folder.is_dir():
            problems.append(PluginProblem(folder.name, str(folder), "import", "plugin folder does not exist"))
            continue
        for path in sorted(folder.glob("*.py")):
            if path.name.startswith("_") or path.resolve() in seen_files:
                continue
            seen_files.add(path.resolve())
            try:
                module = _import_folder_module(path)
            except Exception as exc:
                problems.append(PluginProblem(path.stem, str(path), "import", _describe(exc),
                                              _failing_line(exc)))
                failed.add(path.stem)
                continue
            add(_candidates(module, module), str(path))
    return found, problems, failed


# --------------------------------------------------------------------------- the set

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
        self.timeout_s = timeout_s
        self.max_alerts_per_call = max_alerts_per_call
        self.max_failures = max_failures
        self.isolate = isolate
        self.load_problems = list(load_problems)
        self.plugins: list[LoadedPlugin] = []
        settings = dict(settings or {})
        where_cfg = config_path or "the configuration"
        for inst, name, where in plugins:
            merged = check_plugin_settings(type(inst).settings, settings.get(name, {}), where_cfg,
                                           f"plugins.{name}")
            self.plugins.append(LoadedPlugin(name, inst, where, merged))

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
        cls(found, settings, config_path=config_path)
        return cls(keep, settings, config_path=config_path, load_problems=problems, **kwargs)

    @classmethod
    def from_config(cls, config: Any, **kwargs: Any) -> PluginSet:
        """Build the set from a `stream_viz.config.Config`."""
        p = config.plugins
        return cls.load(p.paths, enable=p.enable, disable=p.disable, settings=p.settings,
                        config_path=str(config.path) if config.path else None, **kwargs)

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
        known = set(graph.nodes) | set(diff.removed_members) | {e.member for e in events}
        by_kind = watched_by_kind(graph, watch)
        alerts: list[Alert] = []
        problems: list[PluginProblem] = []
        for lp in self.plugins:
            if lp.disabled:
                continue
            ctx = PluginContext(t, graph, watch, history, events, diff, lp.settings, lp.state, rates,
                                plugin=lp.name, by_kind=by_kind)
            items, more, problem = self._call(lp, ctx)
            if problem is not None:
                problems.append(problem)
                lp.failures += 1
                if lp.failures >= self.max_failures:
                    lp.disabled = True
                    if lp.worker is not None:
                        lp.worker.stop()  # a hung thread is abandoned; it ends when its call does
                        lp.worker = None
                    problems.append(PluginProblem(lp.name, lp.where, "disabled",
                                                  f"disabled after {lp.failures} failed calls in a row", t=t))
                continue
            lp.failures = 0
            good, bad, reasons = self._screen(lp, items, known)
            if bad:
                problems.append(PluginProblem(lp.name, lp.where, "garbage",
                                              f"dropped {bad} bad item(s): {'; '.join(sorted(reasons))}",
                                              t=t, count=bad))
            if more or len(good) > self.max_alerts_per_call:
                cut = max(0, len(good) - self.max_alerts_per_call)
                good = good[: self.max_alerts_per_call]
                extra = f"{cut}+" if more else f"{cut}"
                problems.append(PluginProblem(lp.name, lp.where, "flood",
                                              f"more than {self.max_alerts_per_call} alerts in one call; "
                                              f"kept the first, dropped {extra}", t=t, count=max(cut, 1)))
            alerts.extend(good)
        return alerts, problems

    def _call(self, lp: LoadedPlugin, ctx: PluginContext) -> tuple[list[Any], bool, PluginProblem | None]:
        call = _Call(ctx, self.max_alerts_per_call)
        start = time.perf_counter()
        if not self.isolate:
            _execute(lp.plugin, call)
        else:
            if lp.worker is None:
                lp.worker = _Worker(lp.plugin, lp.name)
            if lp.worker.busy:
                prev = lp.worker.current
                return [], False, PluginProblem(
                    lp.name, lp.where, "timeout",
                    f"still running its call from t={prev.ctx.t:.3f}; skipped", t=ctx.t)
            lp.worker.submit(call)
            if not call.done.wait(self.timeout_s):
                lp.calls += 1
                lp.seconds += time.perf_counter() - start
                return [], False, PluginProblem(lp.name, lp.where, "timeout",
                                                f"took longer than {self.timeout_s} s; cut off", t=ctx.t)
        lp.calls += 1
        lp.seconds += time.perf_counter() - start
        if call.error is not None:
            return [], False, PluginProblem(lp.name, lp.where, "run", _describe(call.error),
                                            _failing_line(call.error), t=ctx.t)
        return call.result, call.more, None

    @staticmethod
    def _screen(lp: LoadedPlugin, items: list[Any], known: set[str]) -> tuple[list[Alert], int, set[str]]:
        good: list[Alert] = []
        reasons: set[str] = set()
        for a in items:
            if not isinstance(a, Alert):
                reasons.add(f"not an Alert ({type(a).__name__})")
            elif a.severity not in SEVERITIES:
                reasons.add(f"unknown severity {a.severity!r}")
            elif a.member not in known:
                reasons.add(f"unknown member {a.member!r}")
            elif not isinstance(a.t, int | float) or not math.isfinite(a.t):
                reasons.add(f"bad time {a.t!r}")
            elif not isinstance(a.message, str) or not isinstance(a.data, dict):
                reasons.add("message must be str and data a dict")
            else:
                good.append(a if a.plugin == lp.name else replace(a, plugin=lp.name))
        return good, len(items) - len(good), reasons

    def timings(self) -> dict[str, tuple[int, float]]:
        """Plugin name to ``(calls, total seconds)``."""
        return {p.name: (p.calls, p.seconds) for p in self.plugins}

    def close(self) -> None:
        """Stop the worker threads (hung ones are left to end on their own)."""
        for lp in self.plugins:
            if lp.worker is not None:
                lp.worker.stop()
                lp.worker = None
