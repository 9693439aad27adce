"""Settings of the root-cause analysis (the ``[rca]`` section of the config file)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from stream_viz.records import SEVERITIES
from stream_viz.settings import load, setting

POLICIES = ("downstream", "upstream", "both")
METHODS = ("trajectory", "pagerank", "hypothesis", "count")
# Plugins whose alert on a node (or its process) says the fault is IN that member (qos_compat:
# the subscriber's own QoS cannot match its publishers, so its silence is its own doing).
DIRECT_PLUGINS = ("member_gone", "rosout", "diagnostics", "process_resources", "qos_compat")
WEIGHTS = {"topology": 3.0, "direct": 1.0, "cooccurrence": 1.0, "timelag": 1.0, "evidence": 1.0}
# Anomaly strength of one alert, per severity of the one scale (its keys are the only valid ones).
SEVERITY_WEIGHTS = dict(zip(SEVERITIES, (0.25, 0.5, 0.8, 1.0), strict=True))


@dataclass(frozen=True)
class RcaSettings:
    """How the subgraph grows and how root causes are ranked (see docs/rca.md).

    Attributes
    ----------
    policy : {"downstream", "upstream", "both"}
        Which neighbours of an alerting member join the watchlist: successors (the paper's
        rule), predecessors, or both.
    method : {"trajectory", "pagerank", "hypothesis", "count"}
        ``trajectory``: our combined method; ``pagerank``: MicroRCA's personalized PageRank;
        ``hypothesis``: the topology test alone (anomalous, parents healthy); ``count``: alert
        count × severity (GRANO-like relevance, the anomaly-magnitude baseline).
    weights : dict
        Weights of the score components of ``trajectory`` (``topology``, ``direct``,
        ``cooccurrence``, ``timelag``, ``evidence``); zero switches one off.
    severity : dict
        Anomaly strength of one alert per severity (``info``, ``warn``, ``error``, ``fatal``).
    metric : float
        Anomaly strength of metric evidence at full strength (a process's CPU or memory out of
        its own normal range): by default a ``warn``'s, as `process_resources` alerts on the same
        finding, so a metric change alone never outweighs an error such as a crash.
    direct_plugins : tuple of str
        Plugins whose alert on a node or its process is evidence of a fault in that node.
    charge : float
        Factor on a passive member's symptom charged to its publisher node(s).
    window : float
        Only alerts at most this many seconds before the latest one count (0: all).
    tolerance : float
        Seconds within which two alerts count as simultaneous (co-occurrence match, lag
        direction, onset order).
    max_offset : float
        Scale (s) of the co-occurrence penalty for a large ICP offset.
    icp_iterations : int
        Iteration limit of the 1-D ICP.
    max_trajectory : int
        Longest trajectory, in members.
    top_k : int
        How many root causes are reported.
    shortlist : int
        How many candidates (after the cheap topology test) get the full trajectory analysis.
    pagerank_alpha : float
        Damping factor of the PageRank baseline.
    replay : bool
        When a member joins the watchlist, its earlier alerts (kept because it was not watched
        then, within the window) grow the subgraph at once. False: the paper's rule strictly.
    episode_gap : float
        Alerts of one member less than this many seconds apart form one episode (a flapping
        symptom is one episode); an episode is over once this long passed after its last alert.
    incident_hops : int
        Symptoms at most this many hops apart in the graph (data flow in either direction,
        service calls, a node and its process) and close in time form one incident.
    incident_lead : float
        Longest a symptom may begin before that of a member only upstream of it and still be in
        its incident (the upstream one's detection lagged; a cause comes first).
    led_max : float
        Longest an upstream symptom may lead a node's behind silent members and still excuse it
        in full (`symptoms._led`); one that held longer is a standing condition, decayed as any,
        and links no new symptom into its incident (`incidents`).
    """

    policy: str = setting("both", choices=POLICIES)
    method: str = setting("trajectory", choices=METHODS)
    weights: dict[str, float] = setting(WEIGHTS, ge=0, rule=(lambda w: any(w.values()), "at least one > 0"))
    severity: dict[str, float] = setting(SEVERITY_WEIGHTS, ge=0)
    metric: float = setting(SEVERITY_WEIGHTS["warn"], ge=0, le=1)
    direct_plugins: tuple[str, ...] = DIRECT_PLUGINS
    charge: float = setting(0.8, gt=0, le=1)
    window: float = setting(600.0, ge=0)
    tolerance: float = setting(2.0, gt=0)
    max_offset: float = setting(10.0, gt=0)
    icp_iterations: int = setting(20, ge=1)
    max_trajectory: int = setting(12, ge=1)
    top_k: int = setting(5, ge=1)
    shortlist: int = setting(20, ge=1)
    pagerank_alpha: float = setting(0.85, gt=0, lt=1)
    replay: bool = True
    episode_gap: float = setting(15.0, gt=0)
    incident_hops: int = setting(4, ge=1)
    incident_lead: float = setting(10.0, ge=0)
    led_max: float = setting(60.0, gt=0)

    @classmethod
    def from_dict(cls, d: dict[str, Any], where: str) -> RcaSettings:
        """Return settings from a plain dict (the ``[rca]`` table); unknown keys and bad values raise.

        Parameters
        ----------
        d : dict
            Keys as the attributes; missing keys keep their defaults; ``weights`` and ``severity``
            may name only some of their keys.
        where : str
            What the dict came from (a config file path), named in errors.

        Raises
        ------
        ConfigError
            Naming ``where``, the key and the bad value (`stream_viz.settings.check_table`).
        """
        return load(cls, d, where, "rca")
