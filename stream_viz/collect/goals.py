"""Goals of action servers ending, from their ``<action>/_action/status`` topics (observed only).

An action server publishes the status of its goals (``action_msgs/GoalStatusArray``, reliable,
transient-local) whenever one changes. A behaviour that ends — a navigation goal reached,
cancelled or aborted — stops the outputs the server drives (a controller's velocity commands):
like a lifecycle transition, that is a change of the node's state, not a fault, and
``topic_rate`` takes such an end by a topic's last message for the cause of its quiet. Each array
lists every goal the server still remembers, so an end is a goal whose status *changed* to a
terminal one since the last array.

A goal that executes and makes no progress (an action server stuck mid-goal) shows in its
``<action>/_action/feedback`` topic going quiet while the status still says executing: the
tracker also keeps, per action, since when a goal has been executing (`executing_since`) and
when the last feedback came (`feedback`), which the collector puts on the action member
(``executing_since``, ``feedback_at``) for ``services`` to judge.
"""

from __future__ import annotations

from typing import Any

from stream_viz.model.ids import make_id
from stream_viz.records import Event

STATUS_SUFFIX = "/_action/status"
FEEDBACK_SUFFIX = "/_action/feedback"
EXECUTING = 2  # action_msgs/GoalStatus STATUS_EXECUTING
GOAL_STATUS_TYPE = "action_msgs/msg/GoalStatusArray"
# action_msgs/GoalStatus: 4 succeeded, 5 canceled, 6 aborted (the ends of a goal)
ENDS = {4: "succeeded", 5: "canceled", 6: "aborted"}


class GoalTracker:
    """Turns status arrays into one ``goal`` event per goal that ended (kind ``goal``, info)."""

    def __init__(self) -> None:
        self._last: dict[str, dict[bytes, int]] = {}  # status topic -> goal uuid -> its status
        self.executing_since: dict[str, float] = {}  # action -> since when a goal has been executing (s)
        self.feedback: dict[str, float] = {}  # action -> receive time of its newest feedback (s)

    def events(self, topic: str, msg: Any, recv_ns: int, servers: list[str]) -> list[Event]:
        """Return the ``goal`` events of the status array ``msg`` received at ``recv_ns`` on
        ``topic``, one per goal that ended since the previous array, for each of ``servers``
        (none from the first array seen: the goals it lists as ended may have ended long ago)."""
        action = topic.removesuffix(STATUS_SUFFIX)
        first, before = topic not in self._last, self._last.get(topic, {})
        now = {bytes(s.goal_info.goal_id.uuid): int(s.status) for s in msg.status_list}
        self._last[topic] = now
        if EXECUTING not in now.values():
            self.executing_since.pop(action, None)
        else:
            self.executing_since.setdefault(action, recv_ns / 1e9)
        out: list[Event] = []
        if first:  # it lists goals that ended before we looked: no time for their ends
            return out
        for goal, status in now.items():
            if status in ENDS and before.get(goal) != status:
                for server in servers:
                    out.append(Event(recv_ns / 1e9, "goal", make_id("node", server), "info",
                                     f"goal {goal.hex()[:8]} of {action} {ENDS[status]}",
                                     {"action": action, "goal": goal.hex(), "status": ENDS[status]}))
        return out

    def fed(self, topic: str, newest: float) -> None:
        """The feedback topic ``topic``'s newest message was received at ``newest`` (s)."""
        action = topic.removesuffix(FEEDBACK_SUFFIX)
        self.feedback[action] = max(newest, self.feedback.get(action, newest))

    def forget(self, topics: set[str]) -> None:
        """Drop what is known of status topics not in ``topics`` (their servers are gone)."""
        for topic in set(self._last) - topics:
            del self._last[topic]
        actions = {t.removesuffix(STATUS_SUFFIX) for t in topics}
        for known in (self.executing_since, self.feedback):
            for action in set(known) - actions:
                del known[action]
