"""A study's statistics for the dashboard: how far participants got (a funnel by stage), how long those who
finished took, and how many there are per condition and task order (counterbalancing at a glance)."""

from __future__ import annotations

import statistics as stats
from collections import Counter
from typing import Any

from ..db import repository as repo
from .context import Context, aware
from .outcomes import OUTCOMES, outcome_of
from .state import task_sequence
from .studies import study_row

FUNNEL = (("joined", "joined"), ("consented", "gave consent"), ("started", "started the first task"),
          ("finished_tasks", "finished every task"), ("completed", "completed the study"))


def study_statistics(ctx: Context, study_id: str, *, include_pilot: bool = False) -> dict[str, Any]:
    """Funnel by stage, completion-time distribution and condition x task-order counts of a study."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        people = repo.list_participants(s, study_id=study_id, include_pilot=include_pilot)
        started = set(repo.current_task_sessions(s, study_id=study_id))
        reached: Counter[str] = Counter()
        for p in people:
            reached["joined"] += 1
            reached["consented"] += p.consent_at is not None or p.end_reason == "withdrew"
            reached["started"] += p.id in started or p.stage in ("questionnaire", "done")
            reached["finished_tasks"] += p.stage in ("questionnaire", "done")
            reached["completed"] += p.stage == "done"
        seconds = sorted(round((aware(p.finished_at) - aware(p.created_at)).total_seconds(), 1)  # type: ignore[operator]
                         for p in people if p.stage == "done" and p.finished_at and p.created_at)
        cells = Counter((p.condition, tuple(task_sequence(study, p))) for p in people if p.end_reason != "withdrew")
        names = [t["name"] for t in study.tasks]
        return {
            "study_id": study_id, "n_participants": len(people), "include_pilot": include_pilot,
            "funnel": [{"stage": key, "label": label, "n": int(reached[key])} for key, label in FUNNEL],
            "outcomes": {o: sum(1 for p in people if outcome_of(p) == o) for o in OUTCOMES},
            "completion_seconds": {
                "n": len(seconds), "values": seconds,
                "median": stats.median(seconds) if seconds else None,
                "quartiles": [round(q, 1) for q in stats.quantiles(seconds, n=4)] if len(seconds) >= 2 else None,
                "min": seconds[0] if seconds else None, "max": seconds[-1] if seconds else None},
            "cells": [{"condition": condition, "task_order": list(order), "tasks": [names[i] for i in order],
                       "n": n} for (condition, order), n in sorted(cells.items())],
        }
