"""Which objects a study teaches: its own (a scene specification stored with it) or the paper's dinner table; the
learner's task of either, and the robot's question "which objects has this table?" answered from the database."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..core.domain import DINNER_OBJECTS, Domain, get_domain
from ..db import repository as repo
from ..db.engine import Database
from ..scenes.spec import SceneSpec
from .notify import participant_of_key
from .study_definition import study_task


def study_scene(study: Any) -> SceneSpec | None:
    """The study's own objects, or None for the dinner table."""
    return None if not study.objects else SceneSpec.from_json(study.objects)


def study_objects(study: Any) -> tuple[str, ...]:
    """The names of the objects a study's participants place (its own, or the dinner objects)."""
    return DINNER_OBJECTS if not study.objects else tuple(o["name"] for o in study.objects)


def task_name(study: Any) -> str:
    """The learner's task of the study (core.domain): 'dinner' or 'objects:a,b,...'."""
    return study_task(None if not study.objects else study_objects(study))


def study_domain(study: Any) -> Domain:
    """The learner's domain of the study's tasks."""
    return get_domain(task_name(study))


def scene_lookup(db: Database) -> Callable[[str], SceneSpec | None]:
    """The robot's scene_of: a table key's study's own objects, read from the database (None: the dinner table)."""

    def scene_of(key: str) -> SceneSpec | None:
        participant_id = participant_of_key(key)
        if participant_id is None:
            return None
        with db.read() as s:
            objects = repo.study_objects_of_participant(s, participant_id=participant_id)
        return None if not objects else SceneSpec.from_json(objects)

    return scene_of
