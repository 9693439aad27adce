"""A computer of the robot: saturated, out of memory, or out of sight (its agent silent).

Every computer is a host member (`stream_viz.collect.hosts`), the monitor's own one too.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.model.ids import name_of
from stream_viz.records import Alert


class HostState(Plugin):
    """Alerts on a host whose CPU (all its cores) or memory has been nearly full for
    ``saturated_s``: every node on it is slowed, whichever process is to blame (the alert names
    the processes using the most CPU, and how much is used outside them); and on a host whose
    agent went silent (its processes and their metrics are unknown: the agent ended, or the
    computer is off or off the network).

    Full CPU is saturation only while tasks wait for it (``cpu_pressure_percent``, Linux PSI, at
    least ``pressure_percent``): a computer whose every core is busy and nobody waits slows no
    one. Where the kernel gives no pressure, full CPU alone counts. A computer that has run full
    since it was first seen is not saturated by a fault: some robots run their perception
    computer flat out by design. Only a run that began after the host was seen below the level
    is a symptom; an unknown value (a silent agent) ends a run.
    """

    name = "host_state"
    kinds = ("host",)
    settings: ClassVar[dict[str, Any]] = {"cpu_percent": 95.0, "pressure_percent": 20.0,
                                          "mem_percent": 95.0, "saturated_s": 10.0,
                                          "agent_silent": True}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        for host in ctx.members("host"):
            name = name_of(host)
            if ctx.attr(host, "agent") == "silent" and s["agent_silent"]:
                yield ctx.alert(host, "warn", f"the agent on host {name} has been silent for "
                                f"{ctx.attr(host, 'silent_s', 0.0):.0f} s: its processes are unknown "
                                "(the agent ended, or the computer is off or off the network)",
                                symptom="agent_silent")
                continue
            cpu, waited = ctx.value(host, "machine_cpu_percent"), ctx.value(host, "cpu_pressure_percent")
            if waited == waited and waited < s["pressure_percent"] and cpu >= s["cpu_percent"]:
                cpu = s["cpu_percent"] - 1.0  # full, but nobody waits: not saturated
            for attr, value, floor, what in (
                    ("machine_cpu_percent", cpu, s["cpu_percent"], "CPU"),
                    ("machine_mem_percent", ctx.value(host, "machine_mem_percent"), s["mem_percent"],
                     "memory")):
                run = ctx.state.setdefault((host, attr), {})
                since = _run_since(run, ctx.t, value, floor)
                if since is None or ctx.t - since < s["saturated_s"]:
                    continue
                used = f"{ctx.value(host, attr):.0f} % in use for {ctx.t - since:.0f} s"
                if what == "memory" and (limit := ctx.attr(host, "mem_limit_mb")):
                    used = used.replace("in use", f"of its group's limit of {limit:.0f} MB in use", 1)
                if what == "CPU":
                    used += (f", tasks waited for a CPU {waited:.0f} % of the time" if waited == waited
                             else "") + _busiest(ctx, host, name)
                yield ctx.alert(host, "warn", f"host {name} saturated: {what} {used}",
                                symptom=f"host_{what.lower()}", since=since)


def _run_since(run: dict[str, float | None], t: float, value: float, floor: float) -> float | None:
    """When the current run of values ≥ ``floor`` began, if the host was below it before; ``run``
    keeps the start between samples."""
    if value < floor:
        run["low"], run["since"] = t, None
    elif value >= floor:
        if run.get("low") is not None and run.get("since") is None:
            run["since"] = t
    else:  # unknown: not known to be high
        run["since"] = None
    return run.get("since")


def _busiest(ctx: PluginContext, host: str, name: str, n: int = 3) -> str:
    """`` (most: process:b/12 python 180 %, …; outside the robot's processes: 1.6 of 2 CPUs)``: the
    host's processes using the most CPU, and what the rest of the computer uses."""
    cpu = [(ctx.value(p, "cpu_percent"), p) for p in ctx.members("process")
           if ctx.attr(p, "host") == name]
    known = [(c, p) for c, p in cpu if c == c]
    top = sorted(((c, p) for c, p in known if c > 0), reverse=True)[:n]
    parts = ["most: " + ", ".join(f"{p} {ctx.attr(p, 'name', '?')} {c:.0f} %" for c, p in top)] if top else []
    cpus = ctx.attr(host, "cpus")
    if cpus and known:  # launchers above the nodes, read every few samples, are unknown in between
        outside = max(0.0, ctx.value(host, "machine_cpu_percent") * cpus - sum(c for c, _ in known)) / 100
        parts.append(f"outside the robot's processes: {outside:.1f} of {cpus:g} CPUs")
    return f" ({'; '.join(parts)})" if parts else ""
