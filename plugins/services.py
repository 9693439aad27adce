"""Service and action clients left waiting: by an introspected call, by their own log, by a server gone.

What the collector observes without calling anything: the calls of services whose event topic
is on (service introspection: the service's θ ``waiting``/``wait_s``/``response_ms`` and its
attribute ``calls``, the open calls with their client and server), the /rosout lines of a client
that name one of its services or actions or their server (``log`` events list ``services``,
``actions`` and ``nodes``), and a service's or action's ``servers`` becoming empty while it still
has clients. Actions are calls too (a goal sent to an action server): only introspection is
services-only.

Every alert is on the client (its symptom) and names the service and the server in its data
(``service``, ``server``, ``client``): the server is where the fault is looked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import BASELINE_SETTINGS, cached_baseline, rise
from stream_viz.detect.startup import STARTUP_S, starting
from stream_viz.model.ids import name_of
from stream_viz.records import SEVERITY_RANK as RANK
from stream_viz.records import Alert


class Services(Plugin):
    """Alerts on the clients of a service (or the service, when its waiting client is unknown):

    * ``waiting`` (warn): an observed call has been open ≥ ``max(min_wait_s, wait_factor × the
      service's usual response time)`` (its baseline; before one is learnt, the longest it has
      taken; before any answer, ``first_wait_s``: some services take seconds); or (at the
      line's level) the client logged (≥ ``log_level``, WARN) a line naming the service or its
      server — a WARN only when it names it again within ``warn_repeat_s`` of an earlier one (a
      behaviour tree announcing its recovery once is routine; a client that waits says so
      again; 0: at once), an ERROR at once — after the client's first ``startup_s`` (its
      bring-up, when it waits for servers still coming up: the WARNs about a service not ready
      yet) and not while the servers come up: none yet, and the service never had one, in the
      client's first ``missing_s``; or its first server, seen after the monitor's start,
      appeared after the line or less than ``discovery_s`` before it (a client finds a new
      server a moment after the monitor does); or one whose process started less than
      ``startup_s`` before (on a loaded computer a robot's bring-up outlasts a client's first
      seconds);
    * ``slow_response`` (warn): the service's mean response time rose above its own baseline by
      ``max(k·σ, min_rise_ms)`` for ``confirm`` samples;
    * ``server_gone`` (warn): the service had a server and has none while clients remain;
    * ``goal_stalled`` (warn, on the action: its server's progress): a goal has been executing
      and its feedback quiet for ``max(goal_quiet_s, goal_margin ×`` the longest quiet between
      feedback its earlier goals showed``)``, on an action whose goals had feedback while they
      executed (judged from its second goal on: a server that gives no feedback, or gives it
      rarely, says so in its first).

    A service is checked when it or one of its clients is watched.
    """

    name = "services"
    kinds = ("service", "action")
    uses = (cached_baseline, rise)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "k": 6.0,
        "confirm": 2,
        "min_wait_s": 2.0,
        "first_wait_s": 30.0,
        "wait_factor": 3.0,
        "min_rise_ms": 200.0,
        "log_level": "warn",
        "startup_s": STARTUP_S,
        "missing_s": 60.0,
        "discovery_s": 2.0,
        "warn_repeat_s": 30.0,
        "server_gone": True,
        "goal_quiet_s": 3.0,
        "goal_margin": 3.0,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        alerting = ctx.state.setdefault("alerting", set())
        had = ctx.state.setdefault("servers", {})
        first = ctx.state.setdefault("first_served", {})
        after_start = ctx.state.setdefault("checked", False)  # a service seen at the start came earlier
        ctx.state["checked"] = True
        for service in _called(ctx):
            clients = ctx.clients(service)
            if service not in ctx.watch and not any(c in ctx.watch for c in clients):
                continue
            servers = ctx.servers(service)
            yield from _waiting(ctx, service, servers)
            yield from _slow(ctx, service, servers, clients, alerting)
            yield from _stalled_goal(ctx, service, servers)
            if servers:
                if after_start and service not in had:
                    first[service] = ctx.t
                had[service] = servers
            elif had.get(service) and clients and ctx.settings["server_gone"]:
                gone = had[service]
                for c in clients:
                    yield ctx.alert(c, "warn", f"{name_of(service)} has no server any more (was "
                                    f"{', '.join(name_of(g) for g in gone)})", symptom="server_gone",
                                    service=service, server=gone[0], servers=gone, client=c)
        yield from _logged(ctx)


def _stalled_goal(ctx: PluginContext, action: str, servers: list[str]) -> Iterator[Alert]:
    """``goal_stalled``: the action's goal executing without feedback for longer than its goals'
    feedback allows (`Services`). Learnt per action from the collector's ``executing_since`` and
    ``feedback_at``: the longest quiet while executing — between feedback, from a goal's start to
    its first, from its last to the goal's end — that was no symptom, and whether a goal had any."""
    if ctx.kind(action) != "action":
        return
    since, fed = ctx.attr(action, "executing_since"), ctx.attr(action, "feedback_at")
    g = ctx.state.setdefault("goals", {}).setdefault(action, _Goals())
    start = since if g.last is None or since is None else max(since, g.last)
    limit = max(ctx.settings["goal_quiet_s"], ctx.settings["goal_margin"] * g.longest)
    if since is None or (fed is not None and fed > start):  # a goal ended, or feedback came
        end = ctx.t if since is None else fed
        if g.running and not g.stalled:  # the quiet that ended was the server's own rhythm
            g.longest = max(g.longest, end - g.start)
        if since is None:
            g.with_feedback += g.fed
            g.running = g.fed = g.stalled = False
            g.last = None
        else:
            g.running, g.fed, g.stalled, g.start, g.last = True, True, False, fed, fed
        return
    g.running, g.start = True, start
    quiet = ctx.t - start
    g.stalled = bool(g.with_feedback) and quiet > limit
    if g.stalled:
        yield ctx.alert(action, "warn", f"goal executing, no feedback for {quiet:.1f} s (the longest "
                        f"quiet of its goals before: {g.longest:.1f} s)", symptom="goal_stalled",
                        action=action, server=servers[0] if servers else None, quiet_s=quiet)


@dataclass
class _Goals:
    """What one action's goals have shown (`_stalled_goal`)."""

    with_feedback: int = 0  # goals that had feedback while executing
    longest: float = 0.0  # the longest quiet while executing that was no symptom (s)
    running: bool = False  # a goal executes
    fed: bool = False  # it had feedback
    stalled: bool = False  # its quiet is a symptom
    start: float = 0.0  # the current quiet's start: the goal's start or its last feedback
    last: float | None = None  # its last feedback


def _coming_up(ctx: PluginContext, client: str, service: str, servers: list[str], had: bool,
               t: float) -> bool:
    """True when ``service``'s servers were coming up at ``t``: none yet and none ever (``had``)
    in ``client``'s first ``missing_s``; its first server seen less than ``discovery_s`` before
    ``t`` or after it; or one whose process started ``startup_s`` before."""
    s = ctx.settings
    if not servers:
        return not had and starting(ctx, client, t, s["missing_s"])
    first = ctx.state.get("first_served", {}).get(service)
    if first is not None and t < first + s["discovery_s"]:
        return True
    return any(starting(ctx, n, t, s["startup_s"]) for n in servers)


def _called(ctx: PluginContext) -> list[str]:
    """The services and actions of the graph."""
    return [*ctx.members("service"), *ctx.members("action")]


def _waiting(ctx: PluginContext, service: str, servers: list[str]) -> Iterator[Alert]:
    """One alert per client with a call open longer than the service's usual response allows."""
    s = ctx.settings
    calls = ctx.attr(service, "calls") or []
    waiting = ctx.state.setdefault("waiting", set())  # the usual response time stays frozen meanwhile
    if not calls:
        waiting.discard(service)
        return
    base = cached_baseline(ctx, service, "response_ms", frozen=service in waiting)
    usual_ms = base[0] if base is not None and not math.isnan(base[0]) else _longest_ms(ctx, service)
    limit = s["first_wait_s"] if math.isnan(usual_ms) else max(s["min_wait_s"],
                                                               s["wait_factor"] * usual_ms / 1e3)
    longest: dict[str, dict[str, Any]] = {}
    for call in calls:
        waited = call.get("waited_s", 0.0)
        member = call.get("client") or service
        if waited >= limit and waited > longest.get(member, {}).get("waited_s", -1.0):
            longest[member] = call
    waiting.discard(service)
    if longest:
        waiting.add(service)
    for member, call in sorted(longest.items()):
        server = call.get("server") or (servers[0] if len(servers) == 1 else None)
        usual = "" if math.isnan(usual_ms) else f", usually answered in {usual_ms:.0f} ms"
        yield ctx.alert(member, "warn", f"waits {call['waited_s']:.1f} s for {name_of(service)} from "
                        f"{name_of(server) if server else 'an unknown server'}{usual}",
                        symptom="waiting", via="introspection", service=service, server=server,
                        client=call.get("client"), waited_s=call["waited_s"])


def _longest_ms(ctx: PluginContext, service: str) -> float:
    """The longest mean response time the service has shown in the baseline's ``window`` (NaN:
    none answered yet): its usual time until a baseline is learnt (a service called twice a
    minute takes minutes to learn)."""
    _, values = ctx.past(service, "response_ms", last=ctx.settings["window"])
    values = values[~np.isnan(values)]
    return float(values.max()) if len(values) else float("nan")


def _slow(ctx: PluginContext, service: str, servers: list[str], clients: list[str],
          alerting: set) -> Iterator[Alert]:
    risen = rise(ctx, service, "response_ms", ctx.settings["min_rise_ms"], alerting)
    if risen is None:
        return
    value, med = risen
    server = servers[0] if len(servers) == 1 else None
    for member in clients or [service]:
        yield ctx.alert(member, "warn",
                        f"{name_of(service)} answers in {value:.0f} ms, normally {med:.0f} ms",
                        symptom="slow_response", service=service, server=server,
                        client=member if member != service else None, value_ms=value, baseline_ms=med)


def _logged(ctx: PluginContext) -> Iterator[Alert]:
    """A client's log line naming one of its services, or a server of one: it waits on it."""
    floor = RANK.get(ctx.settings["log_level"], RANK["warn"])
    served = ctx.state.get("servers", {})  # the services that had a server
    worst: dict[tuple[str, str], tuple[Any, str | None]] = {}  # the worst line per client and service
    for e in ctx.events:
        if e.kind != "log" or RANK.get(e.level, -1) < floor:
            continue
        named_services = set(e.data.get("services", ())) | set(e.data.get("actions", ()))
        named_nodes = set(e.data.get("nodes", ()))
        if not named_services and not named_nodes:
            continue
        if starting(ctx, e.member, e.t, ctx.settings["startup_s"]):
            continue  # its bring-up: rosout counts the line
        for service in _called(ctx):
            if e.member not in ctx.clients(service):
                continue
            servers = ctx.servers(service)
            hit = [n for n in servers if n in named_nodes]
            if service not in named_services and not hit:
                continue
            if _coming_up(ctx, e.member, service, servers, bool(served.get(service)), e.t):
                continue
            had = worst.get((e.member, service))
            if had is None or RANK.get(e.level, 0) > RANK.get(had[0].level, 0):
                only = servers[0] if len(servers) == 1 else None
                worst[(e.member, service)] = (e, hit[0] if hit else only)
    warned = ctx.state.setdefault("warned", {})  # (client, service) -> its last WARN naming it
    for (client, service), (e, server) in worst.items():
        if RANK.get(e.level, 0) < RANK["error"] and ctx.settings["warn_repeat_s"] > 0:
            before, warned[(client, service)] = warned.get((client, service)), e.t
            if before is None or e.t - before > ctx.settings["warn_repeat_s"]:
                continue  # said once: a retry or a recovery announced, not yet a wait
        # As strong as the complaint: the server it names carries it (RCA `named`).
        level = e.level if e.level in RANK else "warn"
        yield ctx.alert(client, level, f"logged about {name_of(service)}: {e.text}",
                        symptom="waiting", via="log", service=service, server=server, client=client)

