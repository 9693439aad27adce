"""Settings of the root-cause analysis (the ``[rca]`` section of the config file)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from stream_viz.errors import ConfigError

POLICIES = ("downstream", "upstream", "both")
METHODS = ("trajectory", "pagerank", "hypothesis", "count")
WEIGHT_KEYS = ("topology", "direct", "cooccurrence", "timelag", "evidence")
SEVERITY_KEYS = ("info", "warn", "error", "fatal")
# Plugins whose alert on a node (or its process) says the fault is IN that member.
DIRECT_PLUGINS = ("member_gone", "rosout", "diagnostics", "process_resources")


def _default_weights() -> dict[str, float]:
    return {"topology": 3.0, "direct": 1.0, "cooccurrence": 1.0, "timelag": 1.0, "evidence": 1.0}


def _default_severity() -> dict[str, float]:
    return {"info": 0.25, "warn": 0.5, "error": 0.8, "fatal": 1.0}


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
        Anomaly strength of one alert per severity.
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
    """

    policy: str = "both"
    method: str = "trajectory"
    weights: dict[str, float] = field(default_factory=_default_weights)
    severity: dict[str, float] = field(default_factory=_default_severity)
    direct_plugins: tuple[str, ...] = DIRECT_PLUGINS
    charge: float = 0.8
    window: float = 600.0
    tolerance: float = 2.0
    max_offset: float = 10.0
    icp_iterations: int = 20
    max_trajectory: int = 12
    top_k: int = 5
    shortlist: int = 20
    pagerank_alpha: float = 0.85
    replay: bool = True

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
            Naming the key, the bad value and ``where``.
        """
        if not isinstance(d, dict):
            raise ConfigError(f"{where}: [rca] must be a table, not {type(d).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        for key in d:
            if key not in names:
                raise ConfigError(f"{where}: unknown key rca.{key} (known: {', '.join(sorted(names))})")
        base = cls()
        kw: dict[str, Any] = {}
        for key, value in d.items():
            kw[key] = _check(key, value, getattr(base, key), where)
        if "policy" in kw and kw["policy"] not in POLICIES:
            raise ConfigError(f"{where}: rca.policy = {kw['policy']!r}; valid: {', '.join(POLICIES)}")
        if "method" in kw and kw["method"] not in METHODS:
            raise ConfigError(f"{where}: rca.method = {kw['method']!r}; valid: {', '.join(METHODS)}")
        return cls(**kw)


def _bad(where: str, key: str, value: Any, want: str) -> ConfigError:
    return ConfigError(f"{where}: rca.{key} = {value!r}; expected {want}")


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _check(key: str, value: Any, default: Any, where: str) -> Any:
    """Validate one value against the type of its default; return it normalised."""
    if isinstance(default, dict):
        if not isinstance(value, dict):
            raise _bad(where, key, value, f"a table with keys {', '.join(default)}")
        out = dict(default)
        for k, v in value.items():
            if k not in default:
                raise ConfigError(f"{where}: unknown key rca.{key}.{k} (known: {', '.join(default)})")
            if not _number(v) or v < 0:
                raise _bad(where, f"{key}.{k}", v, "a number >= 0")
            out[k] = float(v)
        if key == "weights" and not any(out.values()):
            raise _bad(where, key, value, "at least one weight > 0")
        return out
    if isinstance(default, tuple):
        if not isinstance(value, list | tuple) or not all(isinstance(v, str) for v in value):
            raise _bad(where, key, value, "a list of plugin names")
        return tuple(value)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise _bad(where, key, value, "true or false")
        return value
    if isinstance(default, str):
        if not isinstance(value, str):
            raise _bad(where, key, value, "a string")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise _bad(where, key, value, "an integer >= 1")
        return value
    # floats
    if not _number(value) or value < 0:
        raise _bad(where, key, value, "a number >= 0")
    if key == "charge" and not 0 < value <= 1:
        raise _bad(where, key, value, "a number in (0, 1]")
    if key == "pagerank_alpha" and not 0 < value < 1:
        raise _bad(where, key, value, "a number in (0, 1)")
    if key in ("tolerance", "max_offset") and value <= 0:
        raise _bad(where, key, value, "a number > 0")
    return float(value)
