"""Scores and tables from the recorded runs (pure: plain dicts in, rows and markdown out)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from bench.eval.metrics import Ranked, aggregate, hit_at, scores, to_blocks

OURS_LIVE = "stream-viz (live)"
BASELINE = "rate monitor + first alert"
PEERS = ("BARO", "n-sigma", "ε-Diagnosis", "PyRCA-HT", "PyRCA-RW")
# Faults the demo injects into the target's whole process (a thread burning CPU, allocations, the
# process killed): nothing observable tells the target from the other nodes of its process.
PROCESS_FAULTS = ("crash", "cpu", "leak")
LEVELS = ("strict", "process", "injected")


def truth(run: Mapping, level: str) -> set[str]:
    """The members that count as the root cause at ``level``.

    ``strict``: the target node; ``process``: any node of its process; ``injected``: the
    granularity the fault was injected at (``process`` for `PROCESS_FAULTS`, else ``strict``).
    """
    if level == "injected":
        level = "process" if run["spec"].get("fault") in PROCESS_FAULTS else "strict"
    return set(run[f"truth_{level}"])


def ranked(items: Iterable[str | Sequence[str]]) -> list[Ranked]:
    """A recorded ranking as members and tuples of tied members (JSON keeps a tuple as a list)."""
    return [x if isinstance(x, str) else tuple(x) for x in items]


def method_rankings(run: Mapping, peers: Mapping | None) -> dict[str, list[Ranked]]:
    """Method name → ranking (members or tuples of tied members), ours, baseline and peers."""
    r = run["rankings"]
    out: dict[str, list[Ranked]] = {OURS_LIVE: ranked(r["live"])}
    # ("W0=processes" was an intermediate variant of W0=outputs in a few early runs: not scored)
    out |= {f"ours {k}": ranked(v) for k, v in r.items() if "/" in k and "W0=processes" not in k}
    out[BASELINE] = ranked(r["baseline"])
    for name, res in (peers or {}).items():
        if isinstance(res, dict) and "ranking" in res:
            out[name] = ranked(res["ranking"])
    return out


def score_run(run: Mapping, peers: Mapping | None) -> list[dict]:
    """One row per (method, level) for a faulty run; empty for a fault-free run."""
    if not run["spec"].get("fault"):
        return []
    spec = run["spec"]
    rows = []
    for method, ranking in method_rankings(run, peers).items():
        blocks = to_blocks(ranking, run["expand"])
        for level in LEVELS:
            rows.append(
                {
                    "system": spec["system"],
                    "fault": spec["fault"],
                    "target": spec["target"],
                    "size": spec.get("size"),
                    "rep": spec.get("rep", 0),
                    "method": method,
                    "level": level,
                    **scores(blocks, truth(run, level)),
                }
            )
    return rows


def failed_peers(peers_by_run: Iterable[Mapping]) -> dict[str, str]:
    """Peer → the first error it gave (peers that failed on some run)."""
    out: dict[str, str] = {}
    for p in peers_by_run:
        for name, res in (p or {}).items():
            if isinstance(res, dict) and "error" in res:
                out.setdefault(name, res["error"])
    return out


# An alert stamped up to one sample period before the injection time belongs to it: the sample
# time is taken when a sample starts, the injection time when the fault fires during it.
TOLERANCE = 1.0


def alerts_before(run: Mapping, tol: float = TOLERANCE) -> list[Mapping]:
    """Alerts clearly before the injection (all alerts of a fault-free run)."""
    t_inj = run["injected"].get("t") if run.get("injected") else None
    return [a for a in run["alerts"] if t_inj is None or a["t"] < t_inj - tol]


def latencies(run: Mapping) -> dict[str, float | None]:
    """Seconds from injection to the first alert, to the first alert the fault can explain
    (``detected``: on a member of the run's ``reach``), and to the truth ranked first (live ticks)."""
    t_inj = run["injected"].get("t")
    after = [a for a in run["alerts"] if t_inj is not None and a["t"] >= t_inj - TOLERANCE]
    reach = set(run.get("reach", ()))
    hits = [a["t"] for a in after if a["member"] in reach]
    out: dict[str, float | None] = {
        "first_alert": max(0.0, min(a["t"] for a in after) - t_inj) if after else None,
        "detected": max(0.0, min(hits) - t_inj) if hits else None,
        "baseline_first_flag": run.get("baseline_first_flag_s"),
    }
    for level in LEVELS:
        want = truth(run, level)
        out[f"top1_{level}"] = None
        if t_inj is None:
            continue
        for tick in run["ticks"]:
            if tick["t"] < t_inj or not tick["top"]:
                continue
            # first whatever the tie-breaking: every node the first item stands for is true
            if hit_at(to_blocks(ranked(tick["top"][:1]), run["expand"]), want, 1) == 1.0:
                out[f"top1_{level}"] = max(0.0, tick["t"] - t_inj)
                break
    return out


def accuracy_table(rows: Sequence[Mapping], methods: Sequence[str], by: str | None = None) -> str:
    """Markdown: per method (and per ``by`` value), AC@1 / AC@3 / Avg@5 at each level of `truth`."""
    keys = sorted({r[by] for r in rows}) if by else [None]
    head = (
        ["method"]
        + ([by] if by else [])
        + ["n", "AC@1", "AC@3", "Avg@5", "AC@1 proc", "AC@3 proc", "Avg@5 proc", "AC@1 inj", "AC@3 inj"]
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key in keys:
        for m in methods:
            sel = [r for r in rows if r["method"] == m and (by is None or r[by] == key)]
            if not sel:
                continue
            s = aggregate(r for r in sel if r["level"] == "strict")
            p = aggregate(r for r in sel if r["level"] == "process")
            i = aggregate(r for r in sel if r["level"] == "injected")
            cells = (
                [m]
                + ([str(key)] if by else [])
                + [str(s["n"])]
                + [f"{x[k]:.2f}" for x in (s, p) for k in ("AC@1", "AC@3", "Avg@5")]
                + [f"{i[k]:.2f}" for k in ("AC@1", "AC@3")]
            )
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def fault_matrix(
    rows: Sequence[Mapping], methods: Sequence[str], level: str = "strict", key: str = "AC@1"
) -> str:
    """Markdown: methods × fault kinds, mean ``key`` at ``level``."""
    faults = sorted({r["fault"] for r in rows})
    lines = ["| method | " + " | ".join(faults) + " | all |", "|---|" + "---|" * (len(faults) + 1)]
    for m in methods:
        cells = []
        for f in [*faults, None]:
            sel = [
                r[key]
                for r in rows
                if r["method"] == m and r["level"] == level and (f is None or r["fault"] == f)
            ]
            cells.append(f"{sum(sel) / len(sel):.2f}" if sel else "–")
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def fmt(x: float | None, nd: int = 1) -> str:
    """A number for a table; ``–`` when missing."""
    return "–" if x is None else f"{x:.{nd}f}"


# Sizes (FaultSpec.size) where a larger number is a weaker fault: degrade's is the fraction kept.
LARGER_IS_WEAKER = ("degrade",)


def sweep_rows(runs: Iterable[Mapping]) -> list[dict]:
    """One row per run with a fault size, weakest size first per (system, fault, target).

    Each row: the size, seconds to detection (`latencies` ``detected``) and to the first alert,
    the live diagnosis' expected rank of the truth (strict, process) and AC@1 (process), the
    alerts before the injection.
    """
    rows = []
    for run in runs:
        spec = run["spec"]
        if not spec.get("fault") or spec.get("size") is None:
            continue
        la = latencies(run)
        blocks = to_blocks(ranked(run["rankings"]["live"]), run["expand"])
        strict, proc = scores(blocks, truth(run, "strict")), scores(blocks, truth(run, "process"))
        rows.append({
            "system": spec["system"], "fault": spec["fault"], "target": spec["target"], "size": spec["size"],
            "rep": spec.get("rep", 0), "detected": la["detected"], "first_alert": la["first_alert"],
            "rank_strict": strict["rank"], "rank_process": proc["rank"], "AC@1_process": proc["AC@1"],
            "top1_process": la["top1_process"], "alerts_before": len(alerts_before(run)),
        })
    return sorted(rows, key=lambda r: (r["system"], r["fault"], r["target"], _weakest_first(r), r["rep"]))


def _weakest_first(row: Mapping) -> float:
    return -row["size"] if row["fault"] in LARGER_IS_WEAKER else row["size"]


def floor_rows(sweep: Sequence[Mapping]) -> list[dict]:
    """The detection floor per (system, fault, target) of `sweep_rows` (weakest first).

    ``weakest_detected``: the weakest size detected in every repetition, with its mean detection
    latency and mean live ranks; ``weakest_first``: the weakest size whose truth the live diagnosis
    ranked first (process level) in every repetition. None where no size qualifies.
    """
    groups: dict[tuple, dict[float, list[Mapping]]] = {}
    for r in sweep:
        groups.setdefault((r["system"], r["fault"], r["target"]), {}).setdefault(r["size"], []).append(r)
    out = []
    for (system, fault, target), by_size in groups.items():
        sizes = list(by_size)  # weakest first, as sweep_rows orders them
        detected = [s for s in sizes if all(r["detected"] is not None for r in by_size[s])]
        first = [s for s in sizes if all(r["AC@1_process"] == 1.0 for r in by_size[s])]
        floor = detected[0] if detected else None
        sel = by_size.get(floor, [])
        out.append({
            "system": system, "fault": fault, "target": target, "sizes": sizes,
            "weakest_detected": floor,
            "detected_s": _mean([r["detected"] for r in sel]),
            "rank_strict": _mean([r["rank_strict"] for r in sel]),
            "rank_process": _mean([r["rank_process"] for r in sel]),
            "weakest_first": first[0] if first else None,
        })
    return out


def _mean(xs: Sequence[float | None]) -> float | None:
    """The mean; None if any is None (not ranked, never detected) or there are none."""
    return None if not xs or any(x is None for x in xs) else sum(xs) / len(xs)
