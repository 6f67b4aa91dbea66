"""A study's own objects and goal layout: the typed scene specification, its geometry (shapes, tables, where the
objects start), the arm's reach, and the goal picture. Pure (stdlib and numpy): the services validate and draw
with it; tableteach.sim turns a specification into a MuJoCo scene (sim/scene_mjcf.py)."""

from .spec import SHAPES, SIZE_RANGES, ObjectSpec, SceneSpec, Slot

__all__ = ["SHAPES", "SIZE_RANGES", "ObjectSpec", "SceneSpec", "Slot"]
