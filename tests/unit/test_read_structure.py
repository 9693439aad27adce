"""`read_structure`'s rule for a node name DDS keeps listing after its participant ended."""

from __future__ import annotations

from rclpy.node import NodeNameNonExistentError

from stream_viz.collect.rosgraph import StructureCache, read_structure


class Graph:
    """The graph API of an rclpy node over a literal listing: name → (pubs, subs, servers, clients).
    A ghost is a name listed with no endpoint at all; a name not in ``ends`` is not in the cache."""

    def __init__(self, ends: dict[str, tuple[list, list, list, list]]) -> None:
        self.ends = ends

    def get_node_names_and_namespaces(self):
        return [(n, "/") for n in self.ends]

    def _by_node(self, i: int, name: str, ns: str):
        if name not in self.ends:
            raise NodeNameNonExistentError(name)
        return self.ends[name][i]

    def get_publisher_names_and_types_by_node(self, name, ns):
        return self._by_node(0, name, ns)

    def get_subscriber_names_and_types_by_node(self, name, ns):
        return self._by_node(1, name, ns)

    def get_service_names_and_types_by_node(self, name, ns):
        return self._by_node(2, name, ns)

    def get_client_names_and_types_by_node(self, name, ns):
        return self._by_node(3, name, ns)


ROSOUT = ([("/rosout", ["rcl_interfaces/msg/Log"])], [], [], [])
CAM = ([("/rosout", ["rcl_interfaces/msg/Log"]), ("/img", ["sensor_msgs/msg/Image"])], [], [], [])


def test_a_name_seen_with_endpoints_then_listed_without_any_is_a_ghost_left_out():
    had: set[str] = set()
    first = read_structure(Graph({"cam": CAM, "late": ([], [], [], [])}), "/me", had=had)
    # A name whose endpoints are not discovered yet is kept: it was never seen with any.
    assert sorted(first.nodes) == ["/cam", "/late"] and first.ghosts == []
    assert had == {"/cam"}
    ended = read_structure(Graph({"cam": ([], [], [], []), "late": ROSOUT}), "/me", had=had)
    assert sorted(ended.nodes) == ["/late"] and ended.ghosts == ["/cam"]
    assert ended.topics == {}  # nothing of the ghost's
    back = read_structure(Graph({"cam": CAM, "late": ROSOUT}), "/me", had=had)  # started again
    assert sorted(back.nodes) == ["/cam", "/late"] and back.ghosts == []
    assert back.ends["/img"] == (["/cam"], [])


def test_without_what_was_seen_every_listed_name_is_kept():
    s = read_structure(Graph({"cam": ([], [], [], [])}), "/me")
    assert list(s.nodes) == ["/cam"] and s.ghosts == []


def test_the_cache_keeps_what_was_seen_between_reads():
    cache = StructureCache()
    assert list(cache.get(Graph({"cam": CAM}), ("/me", False, False), 0.0).nodes) == ["/cam"]
    s = cache.get(Graph({"cam": ([], [], [], [])}), ("/me", False, False), 10.0)
    assert s.nodes == {} and s.ghosts == ["/cam"]
