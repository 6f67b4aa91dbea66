"""Study definitions with their own objects, shared by the tests of scenes, the server and the browser."""

from __future__ import annotations

from typing import Any

# A lunch box packed on Table B: five objects (what a study's learner takes), each shape but the bowl.
LUNCH_OBJECTS: list[dict[str, Any]] = [
    {"name": "lunch_box", "shape": "box", "colour": "#c0392b", "size": 12, "slot": {"x": 0, "y": 2}},
    {"name": "apple", "shape": "glass", "colour": "#e74c3c", "size": 7, "slot": {"x": -13, "y": 11}},
    {"name": "napkin", "shape": "plate", "colour": "#f5f5f5", "size": 14, "slot": {"x": 15, "y": -11}},
    {"name": "spoon", "shape": "utensil", "colour": "#95a5a6", "size": 16, "slot": {"x": -16, "y": -6}},
    {"name": "mug", "shape": "cup", "colour": "#2e86c1", "size": 8, "slot": {"x": 13, "y": 10}},
]
LUNCH_TRUTH = "F(lunch_box) & F(napkin) & F(spoon) & (!napkin U lunch_box) & G(!mug)"
# Eight objects, every shape (a study takes up to ten: past five its learner is the exact factorised one).
EIGHT_OBJECTS: list[dict[str, Any]] = [
    *LUNCH_OBJECTS[:4],
    {"name": "mug", "shape": "cup", "colour": "#2e86c1", "size": 8, "slot": {"x": 13, "y": 10}},
    {"name": "fork", "shape": "utensil", "colour": "#7f8c8d", "size": 18, "slot": {"x": 20, "y": 7}},
    {"name": "bowl", "shape": "bowl", "colour": "#3355ff", "size": 12, "slot": {"x": -5, "y": -12}},
    {"name": "glass", "shape": "glass", "colour": "#aed6f1", "size": 6, "slot": {"x": -1, "y": 15}},
]

# Ten objects, the most a study takes, laid out so that every slot is clear and within the arm's reach; the first
# seven are a study of seven (LUNCH_TRUTH is over them).
TEN_OBJECTS: list[dict[str, Any]] = [
    {"name": "lunch_box", "shape": "box", "colour": "#c0392b", "size": 10, "slot": {"x": 4, "y": 10}},
    {"name": "apple", "shape": "glass", "colour": "#e74c3c", "size": 7, "slot": {"x": 2, "y": -2}},
    {"name": "napkin", "shape": "plate", "colour": "#f5f5f5", "size": 12, "slot": {"x": 6, "y": -13}},
    {"name": "spoon", "shape": "utensil", "colour": "#95a5a6", "size": 14, "slot": {"x": -12, "y": 10}},
    {"name": "mug", "shape": "cup", "colour": "#2e86c1", "size": 8, "slot": {"x": -19, "y": 9}},
    {"name": "fork", "shape": "utensil", "colour": "#7f8c8d", "size": 14, "slot": {"x": 15, "y": -11}},
    {"name": "bowl", "shape": "bowl", "colour": "#3355ff", "size": 11, "slot": {"x": 17, "y": 14}},
    {"name": "glass", "shape": "glass", "colour": "#aed6f1", "size": 6, "slot": {"x": 10, "y": -3}},
    {"name": "knife", "shape": "utensil", "colour": "#bdc3c7", "size": 14, "slot": {"x": -5, "y": 11}},
    {"name": "saucer", "shape": "plate", "colour": "#f7dc6f", "size": 12, "slot": {"x": -12, "y": -5}},
]
SEVEN_OBJECTS = TEN_OBJECTS[:7]


def lunch_study(**extra: Any) -> dict[str, Any]:
    """A study that packs a lunch: its own objects, one custom task."""
    return {"name": "Pack a lunch", "objects": LUNCH_OBJECTS,
            "tasks": [{"key": "custom", "ground_truth": LUNCH_TRUTH, "name": "Pack the lunch box"}],
            "conditions": ["active"], "n_practice": 0, "n_demonstrations": 1, "n_queries": 1, "n_tests": 1,
            "questionnaire": [{"id": "learned", "text": "The robot learned the task.", "kind": "likert5"}], **extra}
