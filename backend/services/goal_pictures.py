"""The goal picture of a task of a study with its own objects: Table B with what the task places, as SVG.

The task's ground truth decides what is drawn: the objects it requires (F), the others it allows marked optional,
the ones it forbids (G) named under the table; a task whose ground truth is unknown shows every object."""

from __future__ import annotations

from ..core.domain import get_domain
from ..errors import NotFound
from ..scenes.picture import goal_svg
from .context import Context
from .studies import study_row
from .study_objects import study_scene, task_name


def goal_picture(ctx: Context, study_id: str, task_index: int) -> str:
    """The SVG text; NotFound for a study without its own objects or a task it does not have."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        scene, task_key, tasks = study_scene(study), task_name(study), list(study.tasks)
    if scene is None:
        raise NotFound(f"study {study_id!r} sets the dinner table: its goal pictures are the page's own")
    if not 0 <= task_index < len(tasks):
        raise NotFound(f"study {study_id!r} has no task {task_index}; expected 0 to {len(tasks) - 1}")
    task = tasks[task_index]
    formula = task.get("ground_truth")
    if not formula:
        return goal_svg(scene, task["name"])
    space = get_domain(task_key).clause_space
    clauses = space.clauses_of(space.mask_of_formula(formula))
    required = frozenset(c.first for c in clauses if c.kind == "F")
    forbidden = frozenset(c.first for c in clauses if c.kind == "G")
    optional = frozenset(scene.names) - required - forbidden
    return goal_svg(scene, task["name"], shown=required | optional, optional=optional, forbidden=forbidden)
