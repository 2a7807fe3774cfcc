"""Tests of physinfer.settings: loose values → typed, validated settings dataclasses."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import pytest

from physinfer.errors import UserInputError
from physinfer.settings import (
    MappingSettings,
    check_range,
    converter_for,
    parse_bool,
    require,
    settings_from_mapping,
    settings_to_dict,
    whole_number,
)


@dataclass(frozen=True)
class Demo:
    size: int | tuple[int, int] = 64
    scale: float = 1.0
    count: int = 3
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    colour: tuple[int, int, int] = (1, 2, 3)
    distance: float | None = None
    name: str = "a"
    enabled: bool = True

    def validate(self) -> None:
        check_range("scale", self.scale, 0.5, 2.0)


def test_command_line_strings_become_field_types() -> None:
    demo = settings_from_mapping(
        Demo,
        {"size": "32,48", "scale": "1.5", "count": "4", "direction": "0,1,-1", "colour": "9,8,7",
         "distance": "2.5", "name": "b", "enabled": "off"},
    )
    assert demo == Demo((32, 48), 1.5, 4, (0.0, 1.0, -1.0), (9, 8, 7), 2.5, "b", False)


def test_json_values_become_field_types() -> None:
    demo = settings_from_mapping(
        Demo, {"size": 160.0, "direction": [1, 0, 0], "colour": [4.0, 5, "6"], "distance": None, "name": Path("p")}
    )
    assert demo.size == 160 and isinstance(demo.size, int)
    assert demo.direction == (1.0, 0.0, 0.0) and demo.colour == (4, 5, 6)
    assert demo.distance is None and demo.name == "p"
    assert settings_from_mapping(Demo, {"size": [10, "20"]}).size == (10, 20)
    assert settings_from_mapping(Demo, {"distance": "auto"}).distance is None


def test_missing_keys_take_defaults_and_dict_round_trips() -> None:
    assert settings_from_mapping(Demo, None) == Demo()
    demo = Demo(size=(10, 20), enabled=False)
    as_dict = settings_to_dict(demo)
    assert as_dict["size"] == [10, 20] and as_dict["direction"] == [0.0, 0.0, 1.0]
    assert settings_from_mapping(Demo, as_dict) == demo


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"zoom": 2}, r"unknown demo option 'zoom'; known keys: colour, count"),
        ({"scale": "big"}, r"option scale='big' has the wrong type"),
        ({"count": 2.5}, r"option count=2.5 has the wrong type \(2.5 is not a whole number\)"),
        ({"size": [1, 2, 3]}, r"option size=\[1, 2, 3\] has the wrong type \(expected 2 comma-separated values\)"),
        ({"direction": "1,2"}, r"direction.*expected 3 comma-separated values"),
        ({"enabled": "maybe"}, r"enabled.*expected true or false"),
        ({"name": 3}, r"name=3.*expected a string"),
        ({"scale": 5}, r"scale=5 is out of range; choose a value in \[0.5, 2\]"),
    ],
)
def test_bad_values_are_refused_naming_the_key(values: dict, message: str) -> None:
    with pytest.raises(UserInputError, match=message):
        settings_from_mapping(Demo, values, noun="option", owner="demo")


def test_unsupported_field_types_are_a_programming_error() -> None:
    @dataclass(frozen=True)
    class Odd:
        items: list[int] = ()  # type: ignore[assignment]

        def validate(self) -> None:
            pass

    with pytest.raises(TypeError, match="no conversion"):
        settings_from_mapping(Odd, {})
    with pytest.raises(TypeError, match="not a dataclass"):
        settings_from_mapping(int, {})  # type: ignore[type-var]


def test_small_converters() -> None:
    assert whole_number("7") == 7 and whole_number(7.0) == 7
    with pytest.raises(ValueError, match="whole number"):
        whole_number(7.5)
    assert parse_bool("YES") is True and parse_bool(0) is False
    assert converter_for(float | None)("none") is None
    assert converter_for(tuple[int, int])("3,4") == (3, 4)
    check_range("x", 1.0, 1.0, 1.0)
    with pytest.raises(UserInputError, match="x=nan is out of range"):
        check_range("x", float("nan"), 0.0, 1.0)


def test_require_reports_the_first_failed_check() -> None:
    require([(True, "fine")])
    with pytest.raises(UserInputError, match="^second$"):
        require([(True, "first"), (False, "second"), (False, "third")])


@dataclass(frozen=True)
class Glow(MappingSettings):
    settings_noun: ClassVar[str] = "render parameter"
    settings_owner: ClassVar[str] = "glow"
    radius: float = 1.0
    tint: tuple[int, int, int] = (255, 255, 255)

    def validate(self) -> None:
        check_range("radius", self.radius, 0.0, 10.0)


def test_mixin_gives_from_mapping_and_to_dict() -> None:
    glow = Glow.from_mapping({"radius": "2", "tint": "1,2,3"})
    assert glow == Glow(2.0, (1, 2, 3)) and glow.to_dict() == {"radius": 2.0, "tint": [1, 2, 3]}
    with pytest.raises(UserInputError, match="unknown glow render parameter 'size'"):
        Glow.from_mapping({"size": 3})
    with pytest.raises(UserInputError, match="radius=11 is out of range"):
        Glow.from_mapping({"radius": 11})
