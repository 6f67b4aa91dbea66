"""The codebook of a study's exports (one row per file and column: type, meaning, units or levels, Likert
labels) and exports.zip (every CSV, the codebook and the study definition as JSON)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from typing import Any

from ..core.domain import DINNER_OBJECTS
from ..core.learner_seam import ENUMERATED_UP_TO, path_of
from ..scenes.spec import SIZE_MEANING
from .consistency import FLAG_BELOW
from .context import Context
from .exports import EXPORT_COLUMNS, EXPORTS, export_rows
from .outcomes import OUTCOME_WORDS
from .instruments import INSTRUMENT_KINDS, INSTRUMENTS
from .studies import get_study
from .study_definition import study_task

CODEBOOK_COLUMNS = ["file", "column", "type", "meaning", "units_or_levels", "likert_labels"]

LIKERT5 = "1 = Strongly disagree; 2 = Disagree; 3 = Neither; 4 = Agree; 5 = Strongly agree"
BOOL = "true / false"
TIME = "ISO 8601, UTC"
STAGES = ("consent, instructions, quiz, task, questionnaire (under way); done; withdrawn; screened_out")
END_REASONS = ("declined_consent, withdrew (data deleted), comprehension (failed the quiz), timeout; "
               "empty if the participant did not leave early")
OUTCOME_LEVELS = "; ".join(f"{name} ({words})" for name, words in OUTCOME_WORDS.items()) + "; empty while under way"
TRACE = "JSON list of states, each a sorted list of the objects on the table"
STEP_KINDS = "practice, demonstration, query, test"
DINNER_OBJECT_LEVELS = ", ".join(DINNER_OBJECTS)  # a study with its own objects lists them instead

# column -> (type, meaning, units or levels); a column's entry is shared by every file that has it.
COMMON: dict[str, tuple[str, str, str]] = {
    "participant_id": ("integer", "the participant's number in this server (not a Prolific id)", ""),
    "study_id": ("text", "the study's id on this server", ""),
    "condition": ("category", "the teaching protocol the participant was assigned", "active, random, batch"),
    "task_index": ("integer", "a task's number in the study definition (study.json 'tasks'), from 0", ""),
    "task": ("category", "the task's key in the study definition", "task1, task2, custom, none"),
    "step_kind": ("category", "kind of teaching step", STEP_KINDS),
    "step_index": ("integer", "the step's number within its kind in this task, from 0", ""),
    "acceptable": ("boolean", "the label the learner uses: true for a demonstration, the participant's verdict for "
                   "a query or test (empty: a test left without one)", BOOL),
    "trace": ("json", "what the table showed after each placement", TRACE),
    "created_at": ("datetime", "when the row was recorded", TIME),
}

MEANINGS: dict[str, dict[str, tuple[str, str, str]]] = {
    "participants": {
        "task_order": ("json", "the order in which this participant did the study's tasks (task_index values)",
                       "JSON list of integers"),
        "pilot": ("boolean", "a pilot participant (left out of the exports unless include_pilot=true)", BOOL),
        "stage": ("category", "where the participant is or ended", STAGES),
        "end_reason": ("category", "why the participant left before the end", END_REASONS),
        "timed_out": ("boolean", "idle past the study's timeout; their data are kept", BOOL),
        "quiz_failures": ("integer", "failed attempts at the comprehension quiz", "count"),
        "attention_failed": ("boolean", "at least one attention check in the questionnaire was failed", BOOL),
        "task_index": ("integer", "the task in progress or the last one (task_index in study.json)", ""),
        "prolific_pid": ("text", "PROLIFIC_PID from the study link", ""),
        "external_study_id": ("text", "STUDY_ID from the study link", ""),
        "external_session_id": ("text", "SESSION_ID from the study link", ""),
        "consent_at": ("datetime", "when consent was given", TIME),
        "consent_version": ("text", "version of the consent text agreed to", ""),
        "completion_code": ("text", "the code the participant was shown at the end, for their outcome (empty: "
                            "the study set no code for it, or they are under way)", ""),
        "outcome": ("category", "how the participant's study ended, which decides the code they were shown",
                    OUTCOME_LEVELS),
        "created_at": ("datetime", "when the participant joined", TIME),
        "last_activity_at": ("datetime", "the participant's last request", TIME),
        "finished_at": ("datetime", "when the participant finished or left", TIME),
        "total_seconds": ("number", "time from joining to finishing or leaving (empty while under way)", "seconds"),
        "elapsed_seconds": ("number", "time from joining to finishing or leaving, or to the last activity while "
                            "under way (every participant but those who withdrew: of them only the withdrawal is kept)",
                            "seconds"),
        "n_events": ("integer", "the participant's rows in events.csv (a withdrawn participant's events are deleted "
                     "but the withdrawal)", "count"),
        "seed": ("integer", "the participant's session seed (task i uses seed + i)", ""),
        "tab_hidden": ("integer", "times the study's tab was hidden (another tab or app shown; Page Visibility API) "
                       "while the study was under way", "count"),
        "window_blur": ("integer", "times the study's window lost the focus while the study was under way", "count"),
        "paste": ("integer", "times text was pasted into a questionnaire answer", "count"),
    },
    "events": {
        "seq": ("integer", "the event's number in the participant's log, from 1", ""),
        "kind": ("category", "what happened", "joined, consent, instructions_read, quiz, task_started, place (the "
                 "participant chose an object), placed (the robot reported the table after placing it), "
                 "demonstration, execution_started, execution_finished, replay_watched (the participant watched "
                 "the robot's finished execution again), assessment, task_finished, questionnaire, completed, "
                 "withdrawn, screened_out, restored (the experimenter brought back a participant who timed out or "
                 "was screened out), helped_on (the experimenter moved a stuck participant past their stage), "
                 "tab_hidden (attention telemetry from the page: its tab was hidden), window_blur (the window lost "
                 "the focus), paste (text pasted into an answer), still_here (answered \"are you still there?\")"),
        "object": ("category", "the object placed (place and placed events)", DINNER_OBJECT_LEVELS),
        "labels": ("json", "the objects in their places on the table after a placement, as the robot reported them "
                   "(placed events)", "JSON list"),
        "robot_events": ("json", "the objects the robot placed, in order", "JSON list"),
        "p_acceptable": ("number", "the learner's probability that the robot's execution was acceptable",
                         "probability 0-1"),
        "client_event_id": ("text", "the request's Idempotency-Key", ""),
        "app_version": ("text", "the server version that recorded the event", ""),
        "payload": ("json", "the whole event", "JSON object"),
    },
    "steps": {
        "task_position": ("integer", "the task's place in this participant's order, from 0", ""),
        "shown_at": ("datetime", "when the step was shown: its task started or the previous step was answered",
                     TIME),
        "answered_at": ("datetime", "when the step was answered (demonstration finished or verdict given)", TIME),
        "duration_seconds": ("number", "answered_at minus shown_at", "seconds"),
        "n_objects": ("integer", "objects placed in the step", "count"),
        "learning_step": ("integer", "the belief this step's answer led to: beliefs.csv's step for the same "
                          "participant_id and task_index (empty: practice and tests, which the learner does not "
                          "learn from)", ""),
        "shown_fraction": ("number", "how much of the robot's recorded motion the participant's page had played "
                           "when the verdict was given (1: to the end; empty: not reported, e.g. no 3D view or "
                           "a demonstration)", "fraction 0-1"),
        "replays_watched": ("integer", "times the participant pressed \"Watch it again\" before the verdict "
                            "(empty for demonstrations)", "count"),
    },
    "beliefs": {
        "step": ("integer", "learning step: 0 is the prior, k the belief after the k-th demonstration or assessed "
                 "query", ""),
        "record_kind": ("category", "the step's observation", "empty (prior), practice, demonstration, query"),
        "entropy": ("number", "entropy of the belief over canonical clause sets (every belief here is the study's "
                    "learner's: the authors', or the noise-aware one when study.json's flip_rate is above 0)",
                    "nats"),
        "map_formula": ("text", "the most probable task formula", "LTL over the template clauses"),
        "map_description": ("text", "the most probable formula in plain English", ""),
        "similarity": ("number", "expected similarity of the belief to the ground truth E_P[L(phi, phi*)] "
                       "(empty when the truth is unknown)", "0-1"),
        "map_similarity": ("number", "similarity of the most probable formula to the ground truth", "0-1"),
        **{f"top{i}_formula": ("text", f"the {i}. most probable formula", "") for i in range(1, 6)},
        **{f"top{i}_p": ("number", f"probability of the {i}. most probable formula", "probability 0-1")
           for i in range(1, 6)},
        "p_verdict": ("number", "teacher consistency of a query step: the probability the belief just before it "
                      "gave to the verdict the participant gave (empty for the prior and demonstrations)",
                      "probability 0-1"),
        "consistency_score": ("number", "the participant's consistency in this task: the mean probability of all "
                              "their verdicts, queries and tests (tests against the final belief), each just before "
                              "it was given; the same on every row of the task (empty without verdicts)",
                              "probability 0-1"),
        "consistency_flag": ("boolean", "one of the participant's verdicts in this task (queries and tests) had a "
                             f"probability below {FLAG_BELOW} just before it was given: a reason to look at the "
                             "session (docs/experiments.md, 'Teacher consistency'); the same on every row of the task",
                             BOOL),
        "step_kind": ("category", "the step (steps.csv step_kind) whose answer this belief follows (empty for the "
                      "prior)", "demonstration, query"),
        "step_index": ("integer", "with step_kind: steps.csv's step_index of that step (join beliefs to steps on "
                       "participant_id, task_index, step_kind, step_index)", ""),
    },
    "questionnaire": {
        "item_id": ("text", "the questionnaire item's id (rows below describe each item)", ""),
        "item_kind": ("category", "the item's answer scale", "likert5, rating10, text, attention"),
        "item_text": ("text", "the item's wording", ""),
        "answer": ("mixed", "the answer: a whole number on the item's scale, or text", "see the item rows"),
        "attention_check": ("boolean", "the item is an attention check", BOOL),
        "attention_expected": ("integer", "the answer an attentive participant gives", "1-5"),
        "attention_passed": ("boolean", "the answer was the expected one (empty for other items)", BOOL),
        "answered_at": ("datetime", "when the questionnaire was submitted", TIME),
    },
    "scores": {
        "instrument": ("category", "the standard questionnaire (rows below give each one's scoring and citation)",
                       "sus, tlx, godspeed, trust"),
        "scale": ("category", "the score's scale", "sus; raw_tlx, mental, physical, temporal, performance, effort, "
                  "frustration; anthropomorphism, animacy, likeability, intelligence, safety; trust, distrust"),
        "score": ("number", "the scale's score by the instrument's published rule", "sus and tlx 0-100; godspeed "
                  "1-5; trust 1-7"),
        "n_items": ("integer", "items the score is made of (all answered)", "count"),
        "answered_at": ("datetime", "when the questionnaire was submitted", TIME),
    },
}


# What beliefs.csv's columns mean in a study with more than five objects: its learner is the exact factorised
# one (core.exact, through core.learner_seam), which computes the same posterior without listing any formula.
EXACT_NOTE = (f"; past {ENUMERATED_UP_TO} objects the exact factorised learner computes it without listing formulas "
              "(docs/learner.md)")
EXACT_MEANINGS: dict[str, dict[str, tuple[str, str, str]]] = {
    "beliefs": {
        "entropy": ("number", "entropy of the belief over canonical clause sets, exact" + EXACT_NOTE, "nats"),
        "map_formula": ("text", "the most probable task formula, found exactly by a branch and bound" + EXACT_NOTE
                        + "; among equally probable formulas the first found", "LTL over the template clauses"),
        "similarity": ("number", "expected similarity of the belief to the ground truth E_P[L(phi, phi*)], exact"
                       + EXACT_NOTE + " (empty when the truth is unknown)", "0-1"),
        "top1_formula": ("text", f"past {ENUMERATED_UP_TO} objects: the most probable formula (map_formula); the "
                         "exact learner lists no other formula", ""),
        "top1_p": ("number", "the most probable formula's exact posterior probability", "probability 0-1"),
        **{f"top{i}_formula": ("text", f"empty past {ENUMERATED_UP_TO} objects: the exact learner does not list "
                               "formulas beyond the most probable one (the dashboard shows the clauses most probably "
                               "in the formula instead)", "") for i in range(2, 6)},
        **{f"top{i}_p": ("number", f"empty past {ENUMERATED_UP_TO} objects (see top{i}_formula)", "probability 0-1")
           for i in range(2, 6)},
        "p_verdict": ("number", "teacher consistency of a query step: the probability the belief just before it "
                      "gave to the verdict the participant gave, P(acceptable) of the trace or 1 minus it, exact"
                      + EXACT_NOTE + " (empty for the prior and demonstrations)", "probability 0-1"),
    },
}


def _item_rows(questionnaire: list[dict[str, Any]]) -> Iterator[list[Any]]:
    for item in questionnaire:
        kind = item["kind"]
        anchors = item.get("anchors") or ["", ""]
        if kind in INSTRUMENT_KINDS:
            low, high, step = INSTRUMENT_KINDS[kind]
            levels = f"{low}-{high}" + (f" in steps of {step}" if step != 1 else "")
            labels = f"{low} = {anchors[0]}; {high} = {anchors[1]} (only the ends are labelled)"
        else:
            levels = {"likert5": "1-5", "rating10": "1-10", "text": "free text",
                      "attention": f"1-5; expected {item.get('expected')}"}[kind]
            labels = LIKERT5 if kind in ("likert5", "attention") else ("1 and 10 as the item text says"
                                                                        if kind == "rating10" else "")
        kind_name = "attention check" if kind == "attention" else "questionnaire item"
        if item.get("instrument") in INSTRUMENTS:
            kind_name = f"{INSTRUMENTS[item['instrument']].title} item {item.get('instrument_item')}"
        yield ["questionnaire.csv", f"answer where item_id = {item['id']}", "text" if kind == "text" else "integer",
               f"{kind_name}: {item['text']}", levels, labels]


def _score_rows(questionnaire: list[dict[str, Any]]) -> Iterator[list[Any]]:
    """One row per standard questionnaire in the study: how scores.csv scores it, and its citation."""
    used = dict.fromkeys(item["instrument"] for item in questionnaire if item.get("instrument") in INSTRUMENTS)
    for name in used:
        instrument = INSTRUMENTS[name]
        yield ["scores.csv", f"score where instrument = {name}", "number",
               f"{instrument.title}. Scoring: {instrument.scoring} Source: {instrument.citation}", "", ""]


def codebook_rows(ctx: Context, study_id: str) -> list[list[Any]]:
    """The codebook of a study's exports, header first (NotFound for an unknown study)."""
    study = get_study(ctx, study_id)
    own = study.get("objects") or []
    exact = path_of(study_task([o["name"] for o in own])) == "exact"
    rows = [CODEBOOK_COLUMNS]
    for name in EXPORTS:
        meanings = {**MEANINGS[name], **(EXACT_MEANINGS.get(name, {}) if exact else {})}
        for column in EXPORT_COLUMNS[name]:
            kind, meaning, units = meanings.get(column) or COMMON[column]
            if own and units == DINNER_OBJECT_LEVELS:
                units = ", ".join(o["name"] for o in own)  # the study's own objects
            rows.append([f"{name}.csv", column, kind, meaning, units, ""])
    return (rows + list(_item_rows(study["questionnaire"])) + list(_score_rows(study["questionnaire"]))
            + list(_object_rows(own)))


def _object_rows(objects: list[dict[str, Any]]) -> Iterator[list[Any]]:
    """One row per object of a study with its own objects: what study.json's objects say about it."""
    for o in objects:
        what = SIZE_MEANING.get(o["shape"], "size")
        yield ["study.json", f"objects where name = {o['name']}", "category",
               f"one of the study's own objects (its name is the proposition '{o['name']}' of the formulas): a "
               f"{o['shape']} of {what} {o['size']:g} cm, colour {o['colour']}, its place on Table B at x "
               f"{o['slot']['x']:g} cm, y {o['slot']['y']:g} cm from the table's centre (x to the right, y towards "
               "the robot, as the goal picture shows it)", "", ""]


# codebook type -> Frictionless Table Schema field type (JSON cells stay text: their shape is in the description)
FRICTIONLESS_TYPES = {"integer": "integer", "number": "number", "boolean": "boolean", "datetime": "datetime",
                      "text": "string", "category": "string", "json": "string", "mixed": "any"}


def _field(column: str, kind: str, meaning: str, units: str) -> dict[str, Any]:
    out: dict[str, Any] = {"name": column, "type": FRICTIONLESS_TYPES[kind],
                           "description": f"{meaning} ({units})" if units else meaning}
    if kind == "boolean":
        out.update(trueValues=["true"], falseValues=["false"])
    if kind == "datetime":
        out["format"] = "any"  # ISO 8601 with microseconds and offset
    return out


def datapackage(ctx: Context, study_id: str) -> dict[str, Any]:
    """datapackage.json (Frictionless Data Package) of exports.zip, generated from the codebook: one tabular
    resource per CSV with each column's type and meaning."""
    study = get_study(ctx, study_id)
    rows = codebook_rows(ctx, study_id)[1:]
    resources = []
    for name in (*EXPORTS, "codebook"):
        if name == "codebook":
            fields = [{"name": c, "type": "string"} for c in CODEBOOK_COLUMNS]
        else:
            fields = [_field(column, kind, meaning, units) for file, column, kind, meaning, units, _ in rows
                      if file == f"{name}.csv" and not column.startswith("answer where")]
        resources.append({"name": name, "path": f"{name}.csv", "profile": "tabular-data-resource", "format": "csv",
                          "mediatype": "text/csv", "encoding": "utf-8",
                          "dialect": {"delimiter": ",", "lineTerminator": "\r\n", "header": True},
                          "schema": {"fields": fields, "missingValues": [""]}})
    return {"profile": "tabular-data-package", "name": f"tableteach-{study_id}".lower().replace("_", "-"),
            "title": study["name"], "description": "Exports of a TableTeach study; the meaning of every column is in "
            "codebook.csv and in each field's description. study.json is the study's definition.",
            "resources": resources}


def export_files(ctx: Context, study_id: str, *, include_pilot: bool = False
                 ) -> Iterator[tuple[str, Iterable[list[Any]] | str]]:
    """Every file of exports.zip: (name, rows) for the CSVs and the codebook, (name, text) for study.json and
    datapackage.json."""
    study = get_study(ctx, study_id)
    for name in EXPORTS:
        yield f"{name}.csv", export_rows(ctx, study_id, name, include_pilot=include_pilot)
    yield "codebook.csv", codebook_rows(ctx, study_id)
    yield "study.json", json.dumps(study, indent=2, ensure_ascii=False)
    yield "datapackage.json", json.dumps(datapackage(ctx, study_id), indent=2, ensure_ascii=False)
