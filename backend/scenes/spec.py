"""The typed specification of a study's own objects: each object's name, shape, colour, size and goal slot.

Slots are given as the pictures show Table B from above: centimetres from the table's centre, x to the right and
y towards the robot (up in the pictures). A specification is stored as JSON (to_json / from_json) in the study.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

SHAPES = ("plate", "bowl", "cup", "glass", "utensil", "box")
# Each shape's size in centimetres: a plate's, bowl's, cup's or glass's diameter, a utensil's length, a box's side.
SIZE_RANGES: dict[str, tuple[float, float]] = {"plate": (12.0, 28.0), "bowl": (10.0, 18.0), "cup": (6.0, 10.0),
                                               "glass": (5.0, 8.0), "utensil": (14.0, 22.0), "box": (6.0, 14.0)}
DEFAULT_SIZES: dict[str, float] = {"plate": 20.0, "bowl": 13.0, "cup": 8.0, "glass": 6.5, "utensil": 20.0,
                                   "box": 10.0}
SIZE_MEANING = {"plate": "diameter", "bowl": "diameter", "cup": "diameter", "glass": "diameter",
                "utensil": "length", "box": "side"}
MIN_OBJECTS, MAX_OBJECTS = 2, 10
NAME_PATTERN = r"^[a-z][a-z0-9_]{0,31}$"
COLOUR_PATTERN = r"^#[0-9a-fA-F]{6}$"
RESERVED_NAMES = frozenset({"true", "false"})  # words of the formula language that would not parse as objects


@dataclass(frozen=True)
class Slot:
    """Where an object goes on Table B: centimetres from its centre, x to the right, y towards the robot."""

    x: float
    y: float


@dataclass(frozen=True)
class ObjectSpec:
    """One object of a study's scene."""

    name: str
    shape: str
    colour: str
    size: float  # centimetres (SIZE_MEANING)
    slot: Slot

    def to_json(self) -> dict[str, Any]:
        """The object as stored and shown by the API."""
        return {"name": self.name, "shape": self.shape, "colour": self.colour.lower(), "size": self.size,
                "slot": {"x": self.slot.x, "y": self.slot.y}}


@dataclass(frozen=True)
class SceneSpec:
    """A study's objects in their order (the order of the page's buttons and of the learner's propositions)."""

    objects: tuple[ObjectSpec, ...]

    @property
    def names(self) -> tuple[str, ...]:
        """The objects' names, which are also the task's propositions."""
        return tuple(o.name for o in self.objects)

    def of(self, name: str) -> ObjectSpec:
        """One object by name; KeyError naming the known ones."""
        for o in self.objects:
            if o.name == name:
                return o
        raise KeyError(f"no object {name!r}; expected one of {', '.join(self.names)}")

    def to_json(self) -> list[dict[str, Any]]:
        """The objects as stored and shown by the API."""
        return [o.to_json() for o in self.objects]

    @staticmethod
    def from_json(items: list[dict[str, Any]]) -> "SceneSpec":
        """A specification from to_json's form (already validated; size defaults by shape)."""
        return SceneSpec(tuple(
            ObjectSpec(str(o["name"]), str(o["shape"]), str(o.get("colour") or "#888888").lower(),
                       float(o.get("size") or DEFAULT_SIZES[str(o["shape"])]),
                       Slot(float(o["slot"]["x"]), float(o["slot"]["y"])))
            for o in items))


def name_problem(name: str) -> str | None:
    """Why a name cannot be an object's (None if it can)."""
    if not re.match(NAME_PATTERN, name):
        return (f"{name!r} is not a valid object name: expected lower-case letters, digits and _, starting with a "
                "letter, at most 32 characters (e.g. lunch_box)")
    if name in RESERVED_NAMES:
        return f"{name!r} is a word of the formula language; choose another object name"
    return None
