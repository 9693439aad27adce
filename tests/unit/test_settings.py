"""The one settings mechanism on tiny literal tables: types, constraints, defaults, exact errors."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, dataclass
from pathlib import Path

import pytest

from stream_viz.errors import ConfigError
from stream_viz.settings import (
    Key,
    check_plugin_settings,
    check_table,
    expect_table,
    keys_of,
    load,
    not_a_key,
    plugin_keys,
    setting,
    toml_value,
)


@dataclass(frozen=True)
class Demo:
    rate: float = setting(1.0, gt=0)
    count: int = setting(3, ge=1)
    share: float = setting(0.5, gt=0, le=1)
    on: bool = True
    mode: str = setting("a", choices=("a", "b"))
    names: tuple[str, ...] = ()
    folder: Path | None = None
    weights: dict[str, float] = setting({"x": 1.0, "y": 2.0}, ge=0,
                                        rule=(lambda w: any(w.values()), "at least one > 0"))
    extra: dict[str, int] = not_a_key(dict)


def _error(table, where="f.toml", section="demo"):
    with pytest.raises(ConfigError) as info:
        load(Demo, table, where, section)
    return str(info.value)


def test_keys_come_from_the_annotations_and_setting():
    keys = keys_of(Demo)
    assert list(keys) == ["rate", "count", "share", "on", "mode", "names", "folder", "weights"]
    assert keys["rate"] == Key(float, 1.0, gt=0)
    assert keys["names"] == Key(str, (), tuple)
    assert keys["folder"] == Key(Path, None)
    assert {k: v.expected() for k, v in keys.items()} == {
        "rate": "a number > 0", "count": "an integer >= 1", "share": "a number in (0, 1]",
        "on": "true or false", "mode": "one of a, b", "names": "a list of strings", "folder": "a path",
        "weights": "a table of numbers >= 0, at least one > 0",
    }


def test_values_are_normalised_and_missing_keys_keep_defaults():
    d = load(Demo, {"rate": 2, "names": ["p", "q"], "folder": "out", "weights": {"y": 0}}, "f.toml", "demo")
    assert d == Demo(rate=2.0, names=("p", "q"), folder=Path("out"), weights={"x": 1.0, "y": 0.0})
    assert isinstance(d.rate, float) and isinstance(d.weights["y"], float)
    assert load(Demo, {}, "f.toml", "demo") == Demo()
    with pytest.raises(FrozenInstanceError):
        d.rate = 3.0  # type: ignore[misc]
    assert Demo().weights is not Demo().weights  # a mutable default is copied per instance


@pytest.mark.parametrize(("table", "message"), [
    ({"rate": -1}, "[demo] rate = -1: expected a number > 0"),
    ({"rate": True}, "[demo] rate = true: expected a number > 0"),
    ({"rate": float("nan")}, "[demo] rate = nan: expected a number > 0"),
    ({"rate": float("inf")}, "[demo] rate = inf: expected a number > 0"),
    ({"count": 2.0}, "[demo] count = 2.0: expected an integer >= 1"),
    ({"count": False}, "[demo] count = false: expected an integer >= 1"),
    ({"share": 0}, "[demo] share = 0: expected a number in (0, 1]"),
    ({"on": 1}, "[demo] on = 1: expected true or false"),
    ({"mode": "c"}, '[demo] mode = "c": expected one of a, b'),
    ({"names": "p"}, '[demo] names = "p": expected a list of strings'),
    ({"names": ["p", 1]}, '[demo] names = ["p", 1]: expected a list of strings'),
    ({"weights": {"x": -1}}, "[demo.weights] x = -1: expected a number >= 0"),
    ({"weights": {"z": 1}}, "[demo.weights] unknown key 'z' (known: x, y)"),
    ({"weights": {"x": 0, "y": 0}}, "[demo] weights = {x = 0, y = 0}: expected a table of numbers >= 0, "
                                    "at least one > 0"),
    ({"weights": [1]}, "[demo] weights = [1]: expected a table"),
    ({"extra": {}},
     "[demo] unknown key 'extra' (known: count, folder, mode, names, on, rate, share, weights)"),
])
def test_one_error_format_names_file_section_key_value_and_expectation(table, message):
    assert _error(table) == f"f.toml: {message}"


def test_a_section_that_is_not_a_table_is_named_in_its_parent():
    assert _error(3, section="demo") == "f.toml: demo = 3: expected a table"
    assert _error("x", section="plugins.demo") == 'f.toml: [plugins] demo = "x": expected a table'
    with pytest.raises(ConfigError, match=r'^f\.toml: \[topics\] "/a\.b" = 1: expected a table$'):
        expect_table(1, "f.toml", 'topics."/a.b"')


def test_plugin_keys_take_their_type_from_the_default():
    defaults = {"k": 5.0, "n": 3, "on": False, "level": "warn", "names": ["a"], "any_list": [],
                "anything": None}
    keys = plugin_keys(defaults)
    assert keys["k"] == Key(float, 5.0) and keys["n"] == Key(int, 3) and keys["on"] == Key(bool, False)
    assert keys["names"].expected() == "a list of strings"
    assert keys["any_list"].expected() == "a list of values" and keys["anything"].expected() == "any value"
    got = check_plugin_settings(defaults, {"k": 6, "names": ["b", "c"], "any_list": [1, "x"], "anything": 2},
                                "f.toml", "plugins.p")
    assert got == {"k": 6.0, "n": 3, "on": False, "level": "warn", "names": ["b", "c"], "any_list": [1, "x"],
                   "anything": 2}
    assert isinstance(got["k"], float) and isinstance(got["names"], list)
    got["names"].append("d")
    assert defaults["names"] == ["a"]  # the class's defaults are never shared or changed


@pytest.mark.parametrize(("given", "message"), [
    ({"k": "5"}, '[plugins.p] k = "5": expected a number'),
    ({"k": True}, "[plugins.p] k = true: expected a number"),
    ({"n": 1.5}, "[plugins.p] n = 1.5: expected an integer"),
    ({"on": 0}, "[plugins.p] on = 0: expected true or false"),
    ({"names": ["a", 2]}, '[plugins.p] names = ["a", 2]: expected a list of strings'),
    ({"kk": 1}, "[plugins.p] unknown key 'kk' (known: k, n, names, on)"),
])
def test_plugin_settings_use_the_same_check_and_format(given, message):
    defaults = {"k": 5.0, "n": 3, "on": False, "names": ["a"]}
    with pytest.raises(ConfigError) as info:
        check_plugin_settings(defaults, given, "f.toml", "plugins.p")
    assert str(info.value) == f"f.toml: {message}"


def test_no_keys_lists_none():
    with pytest.raises(ConfigError, match=r"^f\.toml: \[plugins\.p\] unknown key 'x' \(known: none\)$"):
        check_table({}, {"x": 1}, "f.toml", "plugins.p")


def test_values_are_shown_as_written_in_toml():
    assert [toml_value(v) for v in (True, 3, 2.5, "a\"b", [1, "x"], {"k": 1, "a b": False})] == [
        "true", "3", "2.5", '"a\\"b"', '[1, "x"]', '{k = 1, "a b" = false}']
