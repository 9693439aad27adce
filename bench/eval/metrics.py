"""Accuracy of a ranking against the true root cause: AC@k and Avg@5 with exact tie handling.

A ranking of members (nodes, topics, processes) is first mapped to nodes: a topic stands for its
publishers, a process for the nodes it hosts. One ranked item may so stand for several nodes at
once, and members of equal score tie (`tie_blocks`): a *block* of tied nodes. AC@k is the
probability that a true node is among the first k when ties are broken at random (exact,
hypergeometric), so a peer naming a 3-node process gets 1/3 for the strict target at k=1, not 1
and not 0; the same holds for stream-viz naming three nodes with equal scores.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from math import comb

KS = (1, 2, 3, 4, 5)

Ranked = str | tuple[str, ...]  # a member, or members tied at one rank


def tie_blocks(scored: Iterable[tuple[str, float]]) -> list[Ranked]:
    """A ranking with scores, best first → the ranking with members of equal score tied.

    Parameters
    ----------
    scored : iterable of (member, score)
        Best first, as the RCA reports it (equal scores adjacent; scores already rounded).

    Returns
    -------
    list
        A member alone stays a string; consecutive members of equal score become one tuple.
    """
    out: list[list[str]] = []
    last: float | None = None
    for member, score in scored:
        if out and score == last:
            out[-1].append(member)
        else:
            out.append([member])
        last = score
    return [b[0] if len(b) == 1 else tuple(b) for b in out]


def to_blocks(ranked: Iterable[Ranked], expand: Mapping[str, Sequence[str]]) -> list[tuple[str, ...]]:
    """Map a ranking of members to ordered blocks of tied nodes.

    Parameters
    ----------
    ranked : iterable of str or tuple of str
        Members, best first; a tuple is several members tied at one rank.
    expand : mapping
        Member → the nodes it stands for (a node maps to itself). Members missing here, or
        mapping to nothing, are skipped; a node already placed is not placed again.
    """
    placed: set[str] = set()
    blocks: list[tuple[str, ...]] = []
    for item in ranked:
        members = (item,) if isinstance(item, str) else item
        nodes = [n for m in members for n in expand.get(m, ())]
        new = tuple(n for n in dict.fromkeys(nodes) if n not in placed)
        if new:
            placed.update(new)
            blocks.append(new)
    return blocks


def hit_at(blocks: Sequence[Sequence[str]], truth: set[str], k: int) -> float:
    """Probability that a node of ``truth`` is among the first ``k`` (random tie-breaking)."""
    filled = 0
    for b in blocks:
        if filled >= k:
            return 0.0
        t = sum(1 for n in b if n in truth)
        if t:
            m = min(len(b), k - filled)
            return 1.0 - comb(len(b) - t, m) / comb(len(b), m)
        filled += len(b)
    return 0.0


def expected_rank(blocks: Sequence[Sequence[str]], truth: set[str]) -> float | None:
    """Expected 1-based rank of the first node of ``truth``; None when not ranked at all."""
    start = 1
    for b in blocks:
        t = sum(1 for n in b if n in truth)
        if t:
            return start + (len(b) - t) / (t + 1)
        start += len(b)
    return None


def scores(blocks: Sequence[Sequence[str]], truth: set[str]) -> dict[str, float | None]:
    """``{"AC@1".."AC@5", "Avg@5", "rank"}`` of one ranking for one run."""
    out: dict[str, float | None] = {f"AC@{k}": hit_at(blocks, truth, k) for k in KS}
    out["Avg@5"] = sum(out[f"AC@{k}"] for k in KS) / len(KS)
    out["rank"] = expected_rank(blocks, truth)
    return out


def aggregate(rows: Iterable[Mapping[str, float | None]]) -> dict[str, float]:
    """Mean AC@1, AC@3, Avg@5 over runs (``n`` = number of runs)."""
    rows = list(rows)
    if not rows:
        return {"AC@1": float("nan"), "AC@3": float("nan"), "Avg@5": float("nan"), "n": 0}
    return {key: sum(float(r[key]) for r in rows) / len(rows) for key in ("AC@1", "AC@3", "Avg@5")} | {
        "n": len(rows)
    }
