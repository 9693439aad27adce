"""Running one plugin call in isolation, and screening what it returns.

A `Runner` calls one plugin's ``check`` in that plugin's own worker thread with a deadline, so a
plugin that raises or hangs costs one `PluginProblem`, never the caller. `screen` keeps the valid
alerts of a call and turns the rest (garbage, a flood) into problems.
"""

from __future__ import annotations

import itertools
import math
import queue
import threading
import time
from collections.abc import Collection
from dataclasses import dataclass, field, replace
from typing import Any

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.problems import PluginProblem, describe, failing_line
from stream_viz.records import SEVERITIES, Alert


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


class Runner:
    """Calls one plugin's ``check``, timed, in its own worker thread with a deadline.

    Parameters
    ----------
    plugin : Plugin
        The plugin instance.
    name, where : str
        Its name and where it came from (named in problems).
    timeout_s : float
        Longest one call may take before it is cut off.
    limit : int
        Alerts one call may return; an endless generator is read up to 10 times this.
    isolate : bool
        False: call inline (no thread, no deadline), only for benchmarks and debugging.
    """

    def __init__(self, plugin: Plugin, name: str, where: str, *, timeout_s: float, limit: int,
                 isolate: bool = True) -> None:
        self.plugin, self.name, self.where = plugin, name, where
        self.timeout_s, self.limit, self.isolate = timeout_s, limit, isolate
        self.calls = 0
        self.seconds = 0.0
        self._worker: _Worker | None = None  # started on the first call

    def call(self, ctx: PluginContext) -> tuple[list[Any], bool, PluginProblem | None]:
        """Call the plugin on ``ctx``.

        Returns
        -------
        items : list
            What it returned (not screened yet; empty on a problem).
        more : bool
            An endless generator was cut at 10 times the limit.
        problem : PluginProblem or None
            ``run`` (it raised) or ``timeout`` (cut off, or its previous call still runs).
        """
        call = _Call(ctx, self.limit)
        start = time.perf_counter()
        if not self.isolate:
            _execute(self.plugin, call)
        else:
            if self._worker is None:
                self._worker = _Worker(self.plugin, self.name)
            if self._worker.busy:
                prev = self._worker.current
                return [], False, PluginProblem(self.name, self.where, "timeout",
                                                f"still running its call from t={prev.ctx.t:.3f}; skipped",
                                                t=ctx.t)
            self._worker.submit(call)
            if not call.done.wait(self.timeout_s):
                self._count(start)
                return [], False, PluginProblem(self.name, self.where, "timeout",
                                                f"took longer than {self.timeout_s} s; cut off", t=ctx.t)
        self._count(start)
        if call.error is not None:
            return [], False, PluginProblem(self.name, self.where, "run", describe(call.error),
                                            failing_line(call.error), t=ctx.t)
        return call.result, call.more, None

    def _count(self, start: float) -> None:
        self.calls += 1
        self.seconds += time.perf_counter() - start

    def stop(self) -> None:
        """Stop the worker thread; a hung one is abandoned and ends when its call does."""
        if self._worker is not None:
            self._worker.stop()
            self._worker = None


def screen(
    name: str,
    where: str,
    items: list[Any],
    more: bool,
    known: Collection[str],
    limit: int,
    t: float,
) -> tuple[list[Alert], list[PluginProblem]]:
    """Keep the valid alerts of one call, at most ``limit``, stamped with the plugin's ``name``.

    Parameters
    ----------
    name, where : str
        The plugin and where it came from.
    items : list
        What the call returned.
    more : bool
        The call returned more than ``items`` (an endless generator cut short).
    known : collection of str
        The members an alert may name.
    limit : int
        Alerts kept per call.
    t : float
        The sample time (stamped on problems).

    Returns
    -------
    alerts : list of Alert
        The valid ones, in the plugin's order.
    problems : list of PluginProblem
        ``garbage`` (items dropped, counted, the reasons named) and ``flood`` (alerts beyond
        ``limit`` dropped, counted).
    """
    good: list[Alert] = []
    reasons: set[str] = set()
    for a in items:
        why = _wrong(a, known)
        if why:
            reasons.add(why)
        else:
            good.append(a if a.plugin == name else replace(a, plugin=name))
    problems = []
    bad = len(items) - len(good)
    if bad:
        why = "; ".join(sorted(reasons))
        problems.append(PluginProblem(name, where, "garbage", f"dropped {bad} bad item(s): {why}",
                                      t=t, count=bad))
    if more or len(good) > limit:
        cut = max(0, len(good) - limit)
        good = good[:limit]
        extra = f"{cut}+" if more else f"{cut}"
        problems.append(PluginProblem(
            name, where, "flood", f"more than {limit} alerts in one call; kept the first, dropped {extra}",
            t=t, count=max(cut, 1)))
    return good, problems


def _wrong(a: Any, known: Collection[str]) -> str:
    """Why ``a`` is not a valid alert ('' when it is)."""
    if not isinstance(a, Alert):
        return f"not an Alert ({type(a).__name__})"
    if a.severity not in SEVERITIES:
        return f"unknown severity {a.severity!r}"
    if a.member not in known:
        return f"unknown member {a.member!r}"
    if not isinstance(a.t, int | float) or not math.isfinite(a.t):
        return f"bad time {a.t!r}"
    if not isinstance(a.message, str) or not isinstance(a.data, dict):
        return "message must be str and data a dict"
    return ""
