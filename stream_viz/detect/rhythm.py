"""A topic's publishing rhythm, learned from its own past: how long it stays quiet when healthy.

A topic that publishes in bursts or on demand (only while something is in view, only on
request) or once (latched) is quiet most of the time; a continuous topic is never quiet for long.
Silence is a symptom only as a departure from the topic's own rhythm, so the rhythm is learned
from what the collector shows every sample (the receive time of the newest message,
``t - age_s``):

* a **quiet** is the time since the newest message; it is *notable* when it reaches the base
  silence limit (a few periods, at least a second or two: `stream_viz`'s ``topic_rate``);
* a quiet that began and ended between two samples (the monitor was busy, or the gap was
  short) is seen in the collector's longest interval since the last sample (``gap_s``) and
  counts as if a sample had seen it;
* a notable quiet that ends without having been a symptom, nor explained by a cause outside the
  rhythm (``Rhythm.explained``: judged by ``topic_rate``), nor complained of by a publisher
  (``Rhythm.doubted``), is a **healthy gap**, and is learned,
  unless the topic was settled and the quiet reached its silence limit between two samples (a
  silence no sample saw: a sensor dropping out for 1.5 s, learned, would make its longer dropouts
  its rhythm)
  (its length from the newest message before it to the newest after it: an upper bound, off by at
  most a sample period, so a repeat of the same gap never exceeds what was learned);
* a topic is **settled** (its silence can be judged) once it has published without a notable
  quiet for ``settle_s`` (it is continuous), or has shown ``min_gaps`` healthy gaps (its rhythm is
  known), or, having shown some, is in a run longer than ``margin`` times its longest earlier run;
  settled is for good, so a topic that starts to flap stays judged and its flaps are never learned;
* a settled topic's silence limit is the base limit, or ``margin`` times its longest healthy gap
  or its longest healthy quiet of any length, when longer (a quiet judged not notable against a
  rate known only roughly at the time is still the topic's own: a few sparse messages every few
  seconds settle as continuous, and the limit must not fall below what they showed);
* the topic's **rate** (behind the base limit) is its rate while publishing: the median of the
  window's rate over the recent samples whose newest message was less than half a window old. A
  bursty topic's window also holds its quiets (its rate falls as a burst leaves the window, its
  median over time counts the quiets as zeros): against that rate a quiet of its own rhythm would
  not be notable, and the gaps a silence is judged by would go unlearned.

A quiet that ends as the topic's stream restarts its time (its stamps went back: a recording
played in loops, paused between them) was the loop's end: `restarted` marks it healthy even if it
alerted or its publisher complained, so it is learned and the next pauses are within the rhythm.

Pure: `Rhythm` is plain data, changed only by `follow` and `restarted`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from statistics import median

GAP_MEMORY = 32  # healthy gaps and runs remembered per topic (the newest)
RATE_MEMORY = 15  # window rates while publishing, per topic (the newest), behind `Rhythm.rate`
# ``t - age_s`` of one message moves between samples by how long the collector took from the
# sample's time to its topic metrics (graph reads first: milliseconds, more on a loaded host). A
# newer newest message ends a quiet only when the window holds more messages than before, or when
# it is this much newer: less than a sample period, far less than any notable quiet.
SAME_MESSAGE_S = 0.5


@dataclass
class Rhythm:
    """What a topic's publishing has looked like so far.

    Attributes
    ----------
    newest : float or None
        Receive time of the newest message seen (None: none yet).
    run_start : float or None
        The first message of the current run (published without a notable quiet).
    rate : float
        The topic's rate while publishing (Hz; 0 before it is known): the median of ``rates``.
    rates : list of float
        The window's rate at the recent samples that saw the topic publishing, at most
        `RATE_MEMORY`.
    count : int
        Messages in the window at the last sample.
    gaps, runs : list of float
        Healthy gaps (s) and the runs before them (s), oldest first, at most `GAP_MEMORY`.
    settled : bool
        Its silence can be judged (see the module docstring); for good once true.
    peak : float
        The longest quiet seen at a sample during the current quiet.
    longest : float
        The longest quiet, notable or not, that ended with a message and was no symptom.
    departed : bool
        The current quiet was a symptom: it is not learned when it ends.
    explained : bool
        The current quiet has a healthy cause outside the topic's rhythm (its publisher changed
        state, or its input stopped just before it): it is not a symptom, and not learned (its
        length is the cause's, not the topic's).
    doubted : bool
        A publisher complained during the current quiet (``topic_rate``: a WARN or worse, a
        status of its own worse than OK): whatever it was, it is not learned (a sensor dropping
        out with a WARN each time, learned, would make its longer dropouts its rhythm).
    carried : float
        The longest quiet that ended in an earlier run of the robot (s; 0 none): a run the user
        started from (``--healthy``, its `ended`). It counts in `quiet_limit` like the run's own
        gaps; the topic still settles on what this run shows.
    ended : float
        The longest notable quiet that ended with a message in this run, learned or not (a
        silence alerted on, a dropout its publisher complained of; not one a change of state
        explained): what a later run started from this one carries, the user having judged
        this run healthy, its alerts included.
    """

    newest: float | None = None
    run_start: float | None = None
    rate: float = 0.0
    rates: list[float] = field(default_factory=list)
    count: int = 0
    gaps: list[float] = field(default_factory=list)
    runs: list[float] = field(default_factory=list)
    settled: bool = False
    peak: float = 0.0
    longest: float = 0.0
    departed: bool = False
    explained: bool = False
    doubted: bool = False
    carried: float = 0.0
    ended: float = 0.0


def newest_message(t: float, rate: float, age: float) -> float | None:
    """Return the receive time of the newest message in the collector's window at ``t``.

    ``t - age`` when the age is measured; ``t`` when the window has messages but no age (a model
    without it); None when the window has none (``rate`` 0).
    """
    if age == age:
        return t - age
    return t if rate > 0 else None


def follow(r: Rhythm, t: float, newest: float | None, rate: float, *, window_s: float, notable: float,
           settle_s: float, margin: float, min_gaps: int, gap: float = 0.0) -> float | None:
    """Account one sample of a topic in ``r``; return its quiet now (s), None before any message.

    Parameters
    ----------
    r : Rhythm
        The topic's rhythm, updated in place.
    t : float
        The sample time.
    newest : float or None
        `newest_message` of this sample.
    rate : float
        The window's rate (Hz).
    window_s : float
        The collector's rate window: a window without messages means none for at least this long.
    notable : float
        A quiet this long is notable (the base silence limit).
    settle_s : float
        A run this long without a notable quiet makes the topic continuous.
    margin, min_gaps : float, int
        See the module docstring.
    gap : float
        The longest interval between messages received since the previous sample (s; 0 unknown).
    """
    count, before = round(rate * window_s), r.count
    r.count = count
    if newest is not None and (r.newest is None or newest > r.newest):
        if r.newest is None or count > before or newest > r.newest + SAME_MESSAGE_S:
            seen = r.peak  # the longest part of the quiet a sample saw (and topic_rate judged)
            r.peak = max(r.peak, gap)
            _message(r, newest, notable, margin, seen)
        else:  # the same message seen a little later (or one just after it): no quiet ended
            r.newest = newest
    if r.newest is None:
        return None
    quiet = t - r.newest if newest is not None else max(t - r.newest, window_s)
    r.peak = max(r.peak, quiet)
    if rate > 0 and quiet < window_s / 2:  # publishing: the window is mostly the current run
        r.rates = [*r.rates, rate][-RATE_MEMORY:]
        r.rate = median(r.rates)  # not numpy: its per-call overhead dominates on 15 values
    if not r.settled:
        r.settled = _settles(r, settle_s, margin, min_gaps)
    return quiet


def restarted(r: Rhythm) -> None:
    """The topic's stream restarted its time (a ``stamp_reset``): the quiet that ends now was its
    loop's end, a healthy gap to learn though it was a symptom or its publisher complained (a
    log player warning of its loop)."""
    r.departed = r.doubted = False


def _message(r: Rhythm, newest: float, notable: float, margin: float, seen: float) -> None:
    """A message newer than any seen: a notable quiet before it ends, and is learned if healthy.
    On a settled topic, a quiet that reached its limit only between two samples (``seen``: the
    longest a sample saw) was a silence no sample could judge, and is not learned (a flapping
    sensor's first dropout would make the next ones its rhythm); on a settled continuous one,
    neither is a quiet under the limit that would lift it at once (more than ``margin`` × the
    longest quiet yet)."""
    if r.newest is None or r.explained:
        r.run_start = newest
    else:
        # A continuous topic's limit is its base one: what its own hiccups added is no rhythm.
        limit = quiet_limit(r, notable, margin) if r.gaps or r.carried else notable
        missed = r.settled and seen < limit <= r.peak
        # Nor is a settled continuous topic's hiccup that would at once lift its limit above the
        # base, more than ``margin`` × its longest quiet yet: a flaky sensor's first dropout just
        # under the floor, learned, would make every later one healthy.
        jump = (r.settled and not r.gaps and notable / margin < r.peak < notable
                and r.peak > margin * r.longest)
        learn = not (r.departed or missed or r.doubted or jump)
        if learn:
            r.longest = max(r.longest, r.peak)
        if r.peak >= notable:
            r.ended = max(r.ended, newest - r.newest)  # learned or not: the run's to carry
            if learn:
                r.gaps = [*r.gaps, newest - r.newest][-GAP_MEMORY:]
                start = r.newest if r.run_start is None else r.run_start
                r.runs = [*r.runs, r.newest - start][-GAP_MEMORY:]
            r.run_start = newest
    r.newest = newest
    r.peak, r.departed, r.explained, r.doubted = 0.0, False, False, False


def _settles(r: Rhythm, settle_s: float, margin: float, min_gaps: int) -> bool:
    run = r.newest - r.run_start if r.newest is not None and r.run_start is not None else 0.0
    if not r.gaps:
        return run >= settle_s
    return len(r.gaps) >= min_gaps or run >= max(settle_s, margin * max(r.runs))


def quiet_limit(r: Rhythm, base_s: float, margin: float) -> float:
    """Return how long ``r``'s topic may be quiet while healthy: ``base_s``, or ``margin`` × its
    longest healthy gap or quiet, or the gap it carried from an earlier run, when longer."""
    return max(base_s, margin * max([r.longest, r.carried, *r.gaps]))
