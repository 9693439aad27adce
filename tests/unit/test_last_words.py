"""The node that logged as its process died (`stream_viz.collect.last_words`)."""

from __future__ import annotations

from types import SimpleNamespace

from stream_viz.collect.last_words import last_words, newest_lines, note_lines

NODES = ["/rs/gap_detector", "/rs/shopper_detector", "/rs/label_reader"]


def log(name: str, t: float, text: str) -> SimpleNamespace:
    stamp = SimpleNamespace(sec=int(t), nanosec=round((t % 1) * 1e9))
    return SimpleNamespace(name=name, msg=text, stamp=stamp)


def test_note_lines_keeps_each_loggers_newest_line():
    lines: dict[str, tuple[float, str]] = {}
    note_lines(lines, [log("rs.gap_detector", 10.5, "a"), log("rs.gap_detector", 9.0, "older"),
                       log("rs.shopper_detector", 8.0, "b"), SimpleNamespace(name="broken")])
    assert lines == {"rs.gap_detector": (10.5, "a"), "rs.shopper_detector": (8.0, "b")}


def test_the_node_that_logged_last_in_the_span_is_named():
    lines = {"rs.gap_detector": (10.5, "Reloaded planogram (0 bays)"),
             "rs.shopper_detector": (7.0, "track lost"),
             "rs.other_process_node": (10.8, "not of this process")}
    assert last_words(lines, NODES, 9.5, 11.0) == ("/rs/gap_detector", 10.5, "Reloaded planogram (0 bays)")
    assert last_words(lines, NODES, 10.6, 11.0) is None  # nobody of the process spoke then

    def first(shopper_t: float) -> str:
        return last_words({**lines, "rs.shopper_detector": (shopper_t, "lost")}, NODES, 9.5, 11.0)[0]

    # two of them spoke in the span: the later one ran closer to the end
    assert (first(10.7), first(10.2)) == ("/rs/shopper_detector", "/rs/gap_detector")
    # a child logger speaks for its node
    assert last_words({"rs.label_reader.ocr": (10.0, "loaded")}, NODES, 9.5, 11.0)[0] == "/rs/label_reader"


def test_newest_lines_stamp_each_node_with_its_newest_line_its_child_loggers_too():
    lines = {"rs.gap_detector": (10.5, "a"), "rs.gap_detector.lookup": (11.0, "b"),
             "rs.shopper_detector": (8.0, "c"), "rs.not_a_node": (12.0, "d")}
    assert newest_lines(lines, NODES) == {"/rs/gap_detector": 11.0, "/rs/shopper_detector": 8.0}
