"""The one writable-path check of the outputs: report, recording, alert database."""

from __future__ import annotations

import pytest

from stream_viz.detect.store import AlertStore
from stream_viz.errors import OutputError
from stream_viz.output import check_writable


def test_a_writable_path_is_returned_and_nothing_is_left_behind(tmp_path):
    assert check_writable(str(tmp_path / "r.json"), "report") == tmp_path / "r.json"
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "old.json").write_text("keep")
    check_writable(tmp_path / "old.json", "report")
    assert (tmp_path / "old.json").read_text() == "keep"


def test_errors_name_what_the_path_and_why(tmp_path):
    (tmp_path / "file").write_text("x")
    cases = [
        (tmp_path / "no" / "r.json", f"report {tmp_path}/no/r.json: folder {tmp_path}/no does not exist"),
        (tmp_path / "file" / "r.json",
         f"report {tmp_path}/file/r.json: folder {tmp_path}/file is not a folder"),
        (tmp_path, f"report {tmp_path}: is a folder"),
    ]
    for path, message in cases:
        with pytest.raises(OutputError) as info:
            check_writable(path, "report")
        assert str(info.value) == message


def test_the_alert_database_is_checked_by_the_same_function(tmp_path):
    with pytest.raises(OutputError, match=f"^alert database {tmp_path}/no/a.sqlite: folder {tmp_path}/no "):
        AlertStore(tmp_path / "no" / "a.sqlite")
