"""The API's OpenAPI 3.1 document as an integrator generates a client from it: tags with descriptions, short
unique operation ids, optional bodies that may be left out, a partial study for PATCH, and examples."""

from __future__ import annotations

import copy
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from fastapi.routing import APIRoute

TAGS = [
    {"name": "participant", "description": "A participant's session (auth: the participant's token from their "
     "link). Every action answers with the participant's state; a stale or out-of-order one is a 409 with it."},
    {"name": "participant page", "description": "What the participant page needs beside the session: the 3D "
     "view, the robot's motion, replays and the one-tab rule."},
    {"name": "experimenter", "description": "Studies and their participants (auth: the experimenter token)."},
    {"name": "analysis", "description": "The dashboard's read models: live table, histories, curves, replays."},
    {"name": "exports", "description": "CSV files and exports.zip for analysis (described by codebook.csv)."},
    {"name": "prolific", "description": "Reconciliation with Prolific: its submissions export against our "
     "participants, and bonuses in its bulk-bonus format."},
    {"name": "operations", "description": "Health checks for a proxy or an orchestrator."},
]

# Routes whose function names would collide or say too little: path -> operationId.
OPERATION_IDS = {
    "/api/v1/me/execution/replay": "replay_execution",
    "/api/v1/studies/{study_id}/participants/{participant_id}/replays/{task_index}/{step_kind}/{step_index}":
        "get_replay",
    "/api/v1/studies/{study_id}/exports/{name}.csv": "export_csv",
    "/api/v1/me": "get_state",
    "/api/v1/studies/{study_id}/participants/{participant_id}/belief": "get_belief",
    "/api/v1/studies/{study_id}/erasures": "list_erasures",
}

STUDY_EXAMPLE = {
    "name": "Teaching by demonstration vs active queries",
    "tasks": [{"key": "task1"}, {"key": "custom", "ground_truth": "F(bowl) & (!fork U knife)",
                                 "name": "Bowl, knife before fork"}],
    "conditions": ["active", "batch"], "assignment": "balanced", "task_order": "balanced",
    "n_practice": 1, "n_demonstrations": 2, "n_queries": 3, "n_tests": 3,
    "questionnaire": [
        {"id": "learned", "text": "The robot learned the task I was teaching.", "kind": "likert5"},
        {"id": "attn", "text": "To show you read this, choose Disagree.", "kind": "attention", "expected": 2},
        {"id": "overall", "text": "Overall, how well did the robot learn?", "kind": "rating10"},
        {"id": "comments", "text": "Anything else?", "kind": "text", "required": False}],
    "quiz": [{"id": "who", "text": "Who places the objects in a demonstration?", "options": ["I do", "The robot"],
              "correct": 0}],
    "completion_url": "https://app.prolific.com/submissions/complete?cc={code}",
    "completion_code": "C1DONE", "failed_attention_code": "C2ATTN", "timed_out_code": "C3LATE",
    "timeout_minutes": 45,
}

EXAMPLES: dict[tuple[str, str], dict[str, Any]] = {
    ("/api/v1/studies", "post"): {"two tasks, two conditions": {"value": STUDY_EXAMPLE}},
    ("/api/v1/studies/{study_id}", "patch"): {"change the codes of an open study": {
        "value": {"completion_code": "C1DONE", "timed_out_code": "C3LATE", "timeout_minutes": 60}}},
    ("/api/v1/me/placements", "post"): {"place the bowl": {
        "value": {"object": "bowl", "task_index": 0, "step_kind": "demonstration", "step_index": 1}}},
    ("/api/v1/me/questionnaire", "post"): {"each kind of item": {
        "summary": "likert5 and attention: 1-5; rating10: 1-10; text: free text (optional items may be null)",
        "value": {"answers": {"learned": 4, "attn": 2, "overall": 8, "comments": "It learned fast."}}}},
    ("/api/v1/me/quiz", "post"): {"the number of the chosen option": {"value": {"answers": {"who": 0}}}},
    ("/api/v1/me/assessment", "post"): {"a verdict on a query": {
        "value": {"acceptable": True, "task_index": 0, "step_kind": "query", "step_index": 0}}},
}


def operation_id(route: APIRoute) -> str:
    """A short operation id: the endpoint function's name unless OPERATION_IDS gives a clearer one."""
    return OPERATION_IDS.get(route.path_format, route.name)


def _optional_bodies(schema: dict[str, Any]) -> None:
    """An optional body is declared as its model with required false, never as "the model or null"."""
    for ops in schema["paths"].values():
        for op in ops.values():
            body = op.get("requestBody")
            if not body or body.get("required"):
                continue
            for media in body.get("content", {}).values():
                options = media.get("schema", {}).get("anyOf", [])
                refs = [o for o in options if "$ref" in o]
                if len(refs) == 1 and len(options) == 2 and {"type": "null"} in options:
                    media["schema"] = refs[0]
            body["required"] = False


def _study_bodies(schema: dict[str, Any]) -> None:
    """POST takes a study definition; PATCH any of its fields (the others keep their values), nothing else. Both
    are validated by services.study_definition, so the endpoints take the raw JSON and the schema names it."""
    components = schema["components"]["schemas"]
    patch = copy.deepcopy(components["StudyIn"])
    patch.pop("required", None)
    for prop in patch["properties"].values():
        prop.pop("default", None)
    patch["title"] = "StudyPatch"
    patch["description"] = "Any fields of a study definition to change; the others keep their values."
    components["StudyPatch"] = patch
    for path, method, model in (("/api/v1/studies/{study_id}", "patch", "StudyPatch"),
                                ("/api/v1/studies", "post", "StudyIn")):
        body = schema["paths"][path][method]["requestBody"]
        body["content"]["application/json"]["schema"] = {"$ref": f"#/components/schemas/{model}"}


def _examples(schema: dict[str, Any]) -> None:
    for (path, method), examples in EXAMPLES.items():
        body = schema["paths"][path][method]["requestBody"]
        body["content"]["application/json"]["examples"] = examples


def build_openapi(app: FastAPI) -> dict[str, Any]:
    """The app's OpenAPI document (built once)."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes,
                         tags=TAGS)
    _optional_bodies(schema)
    _study_bodies(schema)
    _examples(schema)
    app.openapi_schema = schema
    return schema


def install(app: FastAPI) -> None:
    """Serve this document at /openapi.json."""
    app.openapi = lambda: build_openapi(app)  # type: ignore[method-assign]
