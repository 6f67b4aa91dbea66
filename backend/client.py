"""Python client of the study server (httpx) and a scripted teacher that completes a session over HTTP.

The scripted teacher is the paper's simulated teacher (tableteach.core.teachers) speaking the same
participant API as the browser page: it demonstrates by placing objects one at a time, lets the
robot execute each query and test, and assesses the trace the server reports.
"""

from __future__ import annotations

import io
import time
import uuid
import zipfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Self
from urllib.parse import quote

import httpx
import numpy as np

from .core.domain import DINNER_OBJECTS, DINNER_TASK_FORMULAS, get_domain, objects_task
from .core.metrics import similarity
from .core.teachers import DEFAULT_DEMO_MODE, SimulatedTeacher

RETRIES = 4  # attempts per request: network errors, 503 (database busy) and 429 (too many wrong keys)
MAX_WAIT = 30.0  # seconds: the longest Retry-After honoured before giving up


class ApiError(Exception):
    """The server refused a request: status, its message and (for 409) the current state."""

    def __init__(self, status: int, detail: str, state: dict[str, Any] | None = None,
                 errors: list[dict[str, str]] | None = None) -> None:
        super().__init__(f"HTTP {status}: {detail}")
        self.status, self.detail, self.state, self.errors = status, detail, state, errors


def retry_after(response: httpx.Response, attempt: int) -> float:
    """Seconds to wait before retrying a 503 or 429: its Retry-After (seconds), else a short backoff."""
    try:
        return min(MAX_WAIT, max(0.0, float(response.headers.get("Retry-After", ""))))
    except ValueError:
        return min(MAX_WAIT, 0.2 * 2**attempt)


class _Base:
    """Shared HTTP plumbing: JSON, error decoding, bounded retries of network errors, 503 and 429 (honouring
    Retry-After) for requests that are safe to repeat (GETs, and POSTs with an Idempotency-Key)."""

    def __init__(self, server: str, *, token: str | None = None, timeout: float = 30.0,
                 on_request: Callable[[str, float, int], None] | None = None,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.server = server.rstrip("/")
        self.http = httpx.Client(base_url=self.server, timeout=timeout)
        self.token = token
        self.on_request = on_request
        self.sleep = sleep

    def close(self) -> None:
        """Close the connection pool."""
        self.http.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _request(self, method: str, path: str, *, json: Any = None, key: str | None = None,
                 params: dict[str, Any] | None = None, csv: str | None = None,
                 extra_headers: dict[str, str] | None = None) -> httpx.Response:
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        headers.update(extra_headers or {})
        if key is not None:
            headers["Idempotency-Key"] = key
        if csv is not None:
            headers["Content-Type"] = "text/csv"
        repeatable = method in ("GET", "DELETE", "PUT") or key is not None  # a PUT replaces: repeating is safe
        for attempt in range(RETRIES):
            started = time.perf_counter()
            try:
                response = self.http.request(method, path, json=json, headers=headers, params=params,
                                             content=None if csv is None else csv.encode())
            except httpx.TransportError:
                # Safe to resend: GETs change nothing and POSTs carry the same Idempotency-Key.
                if attempt == RETRIES - 1 or not repeatable:
                    raise
                self.sleep(0.2 * 2**attempt)
                continue
            if self.on_request is not None:
                self.on_request(f"{method} {path}", time.perf_counter() - started, response.status_code)
            # 429 is answered before anything is done; 503 means nothing was stored (safe when repeatable).
            busy = response.status_code == 429 or (response.status_code == 503 and repeatable)
            if busy and attempt < RETRIES - 1:
                self.sleep(retry_after(response, attempt))
                continue
            if response.status_code >= 400:
                try:
                    body = response.json()
                except ValueError:
                    body = {"detail": response.text}
                raise ApiError(response.status_code, str(body.get("detail")), body.get("state"), body.get("errors"))
            return response
        raise AssertionError("unreachable")

    def _json(self, method: str, path: str, body: Any = None, *, idempotent: bool = True,
              params: dict[str, Any] | None = None) -> Any:
        key = str(uuid.uuid4()) if method == "POST" and idempotent else None
        response = self._request(method, path, json=body, key=key, params=params)
        return None if response.status_code == 204 else response.json()


class ParticipantClient(_Base):
    """The participant API, every endpoint (the token comes from join())."""

    _held_state: tuple[str, dict[str, Any]] | None = None  # the last state and its ETag, for conditional reads

    def join(self, study_id: str, *, prolific_pid: str | None = None, session_id: str | None = None,
             external_study_id: str | None = None) -> dict[str, Any]:
        """Join a study; remembers the token. Rejoining with a prolific_pid needs the same session_id (or client)."""
        body = {k: v for k, v in (("prolific_pid", prolific_pid), ("session_id", session_id),
                                  ("study_id", external_study_id)) if v}
        out = self._request("POST", f"/api/v1/studies/{study_id}/join", json=body).json()
        self.token, self._held_state = out["token"], None
        return out

    def state(self) -> dict[str, Any]:
        """The current state: a conditional read, so an unchanged state (304) returns the last answer again."""
        held = self._held_state
        response = self._request("GET", "/api/v1/me", extra_headers={"If-None-Match": held[0]} if held else None)
        if response.status_code == 304 and held:
            return held[1]
        state: dict[str, Any] = response.json()
        tag = response.headers.get("etag")
        self._held_state = (tag, state) if tag else None
        return state

    def consent(self, version: str, agree: bool = True) -> dict[str, Any]:
        """Agree to (or decline) the consent text of this version."""
        return self._json("POST", "/api/v1/me/consent", {"agree": agree, "consent_version": version})

    def instructions(self) -> dict[str, Any]:
        """Mark the instructions as read."""
        return self._json("POST", "/api/v1/me/instructions")

    def quiz(self, answers: dict[str, int]) -> dict[str, Any]:
        """Answer the comprehension quiz (item id -> number of the chosen option, from 0)."""
        return self._json("POST", "/api/v1/me/quiz", {"answers": answers})

    def place(self, obj: str, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Place an object during a demonstration."""
        return self._json("POST", "/api/v1/me/placements", {"object": obj, **(guard or {})})

    def finish(self, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """End the demonstration."""
        return self._json("POST", "/api/v1/me/demonstration/finish", guard or {})

    def execute(self, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Let the robot carry out the current query or test."""
        return self._json("POST", "/api/v1/me/execution", guard or {})

    def replay_execution(self, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Watch the robot's finished execution again (logged as replay_watched)."""
        return self._json("POST", "/api/v1/me/execution/replay", guard or {})

    def assess(self, acceptable: bool | None, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Judge the robot's finished execution."""
        return self._json("POST", "/api/v1/me/assessment", {"acceptable": acceptable, **(guard or {})})

    def questionnaire(self, answers: dict[str, Any]) -> dict[str, Any]:
        """Answer the questionnaire."""
        return self._json("POST", "/api/v1/me/questionnaire", {"answers": answers})

    def withdraw(self) -> dict[str, Any]:
        """Withdraw (after consent): the participant's recorded data are deleted."""
        return self._json("POST", "/api/v1/me/withdraw")

    def view(self) -> dict[str, Any]:
        """The 3D view of the current step: {available, url}."""
        return self._json("POST", "/api/v1/me/view", idempotent=False)

    def top_view(self) -> dict[str, Any]:
        """The 2D view: the tables from above and the current step's recorded motion, if any."""
        return self._json("GET", "/api/v1/me/top-view")

    def robot(self) -> dict[str, Any]:
        """Whether the robot is moving and what it is doing."""
        return self._json("GET", "/api/v1/me/robot")

    def claim_tab(self, tab_id: str, *, takeover: bool = False) -> dict[str, Any]:
        """Hold (or take over) the page's one-tab lease."""
        return self._json("POST", "/api/v1/me/tab", {"tab_id": tab_id, "takeover": takeover}, idempotent=False)

    def release_tab(self, tab_id: str) -> None:
        """Free the page's lease at once."""
        self._request("POST", "/api/v1/me/tab/release", json={"tab_id": tab_id})

    def signal(self, kind: str, field: str | None = None) -> None:
        """One signal of the page: tab_hidden, window_blur, paste (field: the item pasted into) or still_here."""
        self._request("POST", "/api/v1/me/signals", json={"kind": kind, **({"field": field} if field else {})})


class ExperimenterClient(_Base):
    """The experimenter API, every endpoint (token: the server's experimenter secret)."""

    def _study(self, study_id: str, tail: str = "") -> str:
        return f"/api/v1/studies/{quote(study_id, safe='')}{tail}"

    def health(self) -> dict[str, Any]:
        """The server's health check."""
        return self._json("GET", "/healthz")

    def list_studies(self, *, include_archived: bool = False) -> list[dict[str, Any]]:
        """Every study, newest first (archived ones only if asked for)."""
        return self._json("GET", "/api/v1/studies", params={"include_archived": include_archived})

    def delete_study(self, study_id: str) -> None:
        """Delete a study without participants (409 if it has any: archive it instead)."""
        self._request("DELETE", self._study(study_id))

    def archive_study(self, study_id: str) -> dict[str, Any]:
        """Hide a study from the list (an open one is closed first)."""
        return self._json("POST", self._study(study_id, "/archive"), idempotent=False)

    def unarchive_study(self, study_id: str) -> dict[str, Any]:
        """Show an archived study in the list again."""
        return self._json("POST", self._study(study_id, "/unarchive"), idempotent=False)

    def statistics(self, study_id: str, *, include_pilot: bool = False) -> dict[str, Any]:
        """Funnel by stage, completion times and condition x task-order counts."""
        return self._json("GET", self._study(study_id, "/statistics"), params={"include_pilot": include_pilot})

    def instruments(self) -> list[dict[str, Any]]:
        """The standard questionnaires (items, scoring, citations)."""
        return self._json("GET", "/api/v1/instruments")

    def get_study(self, study_id: str) -> dict[str, Any]:
        """One study."""
        return self._json("GET", self._study(study_id))

    def study_spec(self, study_id: str) -> dict[str, Any]:
        """The study as the definition that would create it again."""
        return self._json("GET", self._study(study_id, "/spec"))

    def create_study(self, spec: dict[str, Any]) -> dict[str, Any]:
        """Create a study (draft)."""
        return self._json("POST", "/api/v1/studies", spec, idempotent=False)

    def update_study(self, study_id: str, changes: dict[str, Any]) -> dict[str, Any]:
        """Change some fields of a study (an open one: only its live fields)."""
        return self._json("PATCH", self._study(study_id), changes)

    def clone_study(self, study_id: str) -> dict[str, Any]:
        """A draft copy of a study."""
        return self._json("POST", self._study(study_id, "/clone"), idempotent=False)

    def open_study(self, study_id: str) -> dict[str, Any]:
        """Open a study."""
        return self._json("POST", self._study(study_id, "/open"), idempotent=False)

    def close_study(self, study_id: str) -> dict[str, Any]:
        """Close a study."""
        return self._json("POST", self._study(study_id, "/close"), idempotent=False)

    def reset_pilot(self, study_id: str) -> dict[str, Any]:
        """Erase every pilot participant of a study."""
        return self._json("POST", self._study(study_id, "/pilot/reset"), idempotent=False)

    def participants(self, study_id: str) -> list[dict[str, Any]]:
        """Participants with live status."""
        return self._json("GET", self._study(study_id, "/participants"))

    def erase_participant(self, study_id: str, participant_id: int) -> None:
        """Erase one participant's data (an audit entry is kept)."""
        self._request("DELETE", self._study(study_id, f"/participants/{int(participant_id)}"))

    def restore_participant(self, study_id: str, participant_id: int) -> dict[str, Any]:
        """Bring back a participant who timed out or was screened out."""
        return self._json("POST", self._study(study_id, f"/participants/{int(participant_id)}/restore"),
                          idempotent=False)

    def help_participant(self, study_id: str, participant_id: int) -> dict[str, Any]:
        """Move a stuck participant past their stage."""
        return self._json("POST", self._study(study_id, f"/participants/{int(participant_id)}/help"),
                          idempotent=False)

    def erasures(self, study_id: str) -> list[dict[str, Any]]:
        """The study's erasure audit log."""
        return self._json("GET", self._study(study_id, "/erasures"))

    def belief(self, study_id: str, participant_id: int) -> dict[str, Any]:
        """A participant's belief summary."""
        return self._json("GET", self._study(study_id, f"/participants/{int(participant_id)}/belief"))

    def what_if(self, study_id: str, participant_id: int, learners: list[str] | None = None) -> dict[str, Any]:
        """A participant's recorded data replayed through other learners (each a spec such as "flip=0.1")."""
        return self._json("GET", self._study(study_id, f"/participants/{int(participant_id)}/what-if"),
                          params={"learner": list(learners or [])})

    def live(self, study_id: str, *, dropout_minutes: float | None = None) -> dict[str, Any]:
        """The dashboard's live table."""
        params = {} if dropout_minutes is None else {"dropout_minutes": dropout_minutes}
        return self._json("GET", self._study(study_id, "/live"), params=params)

    def history(self, study_id: str, participant_id: int) -> dict[str, Any]:
        """One participant's events, executions and beliefs."""
        return self._json("GET", self._study(study_id, f"/participants/{int(participant_id)}/history"))

    def curves(self, study_id: str, *, finished_only: bool = False, include_pilot: bool = False) -> dict[str, Any]:
        """Learning curves per condition."""
        return self._json("GET", self._study(study_id, "/curves"),
                          params={"finished_only": finished_only, "include_pilot": include_pilot})

    def replay(self, study_id: str, participant_id: int, task_index: int, step_kind: str,
               step_index: int) -> dict[str, Any]:
        """A recorded robot motion of one step."""
        return self._json("GET", self._study(study_id, f"/participants/{int(participant_id)}/replays/"
                                             f"{int(task_index)}/{quote(step_kind)}/{int(step_index)}"))

    def describe_formula(self, formula: str) -> dict[str, Any]:
        """A formula in canonical form and in plain words."""
        return self._json("GET", "/api/v1/formulas/describe", params={"formula": formula})

    def export(self, study_id: str, name: str, *, include_pilot: bool = False) -> str:
        """One CSV export (or codebook) as text (pilot participants only if include_pilot)."""
        return self._request("GET", self._study(study_id, f"/exports/{quote(name)}.csv"),
                             params={"include_pilot": include_pilot}).text

    def export_zip(self, study_id: str, *, include_pilot: bool = False) -> bytes:
        """exports.zip: every CSV, the codebook, datapackage.json and study.json."""
        return self._request("GET", self._study(study_id, "/exports/exports.zip"),
                             params={"include_pilot": include_pilot}).content

    # Reconciliation with Prolific

    def upload_submissions(self, study_id: str, csv_text: str) -> dict[str, Any]:
        """Upload Prolific's submissions export (CSV text); it replaces the earlier upload."""
        return self._request("PUT", self._study(study_id, "/prolific/submissions"), csv=csv_text).json()

    def reconciliation(self, study_id: str) -> dict[str, Any]:
        """Per Prolific id: Prolific's status against ours, with mismatches in words."""
        return self._json("GET", self._study(study_id, "/prolific/reconciliation"))

    def bonus_rule(self, study_id: str) -> dict[str, Any]:
        """The study's bonus rule: {amounts: {outcome: amount}}."""
        return self._json("GET", self._study(study_id, "/prolific/bonus-rule"))

    def set_bonus_rule(self, study_id: str, amounts: dict[str, float]) -> dict[str, Any]:
        """Set the bonus per outcome (outcomes left out get none)."""
        return self._json("PUT", self._study(study_id, "/prolific/bonus-rule"), {"amounts": amounts})

    def bonus_file(self, study_id: str) -> str:
        """The bulk-bonus file from the rule: lines "participant id,amount"."""
        return self._request("GET", self._study(study_id, "/prolific/bonuses.csv")).text

    # Accounts and the audit log

    def login(self, name: str, password: str) -> dict[str, Any]:
        """Log in with a name and password; from now on this client uses the 12-hour token it gets."""
        out = self._json("POST", "/api/v1/login", {"name": name, "password": password}, idempotent=False)
        self.token = out["token"]
        return out

    def whoami(self) -> dict[str, Any]:
        """The name and role behind this client's token."""
        return self._json("GET", "/api/v1/whoami")

    def change_password(self, current: str, new: str) -> dict[str, Any]:
        """Change the logged-in person's own password (their other dashboard logins end)."""
        return self._json("POST", "/api/v1/password", {"current_password": current, "new_password": new},
                          idempotent=False)

    def people(self) -> list[dict[str, Any]]:
        """Every account (owner only)."""
        return self._json("GET", "/api/v1/accounts")

    def add_person(self, name: str, role: str, password: str | None = None) -> dict[str, Any]:
        """Create an account with a role (owner only)."""
        return self._json("POST", "/api/v1/accounts", {"name": name, "role": role, "password": password},
                          idempotent=False)

    def disable_person(self, name: str) -> dict[str, Any]:
        """Disable an account: its tokens stop at once (owner only)."""
        return self._json("POST", f"/api/v1/accounts/{quote(name, safe='')}/disable", idempotent=False)

    def set_password(self, name: str, password: str) -> dict[str, Any]:
        """Set a person's password (owner only); their dashboard logins end."""
        return self._json("POST", f"/api/v1/accounts/{quote(name, safe='')}/password", {"password": password},
                          idempotent=False)

    def issue_token(self, name: str, *, label: str = "api", days: float = 90) -> dict[str, Any]:
        """A new API token for a person (owner only): {token, id, expires_at, ...}; the token is shown only here."""
        return self._json("POST", f"/api/v1/accounts/{quote(name, safe='')}/tokens", {"label": label, "days": days},
                          idempotent=False)

    def tokens(self) -> list[dict[str, Any]]:
        """Every API token's record, never the token (owner only)."""
        return self._json("GET", "/api/v1/accounts/all-tokens")

    def revoke_token(self, token_id: int) -> dict[str, Any]:
        """Revoke an API token (owner only)."""
        return self._json("DELETE", f"/api/v1/accounts/tokens/{int(token_id)}")

    def audit(self, *, limit: int = 1000) -> list[dict[str, Any]]:
        """The audit log, newest first."""
        return self._json("GET", "/api/v1/audit", params={"limit": limit})

    def audit_csv(self) -> str:
        """The whole audit log as CSV, oldest first."""
        return self._request("GET", "/api/v1/audit.csv").text

    def export_all(self, study_id: str, out_dir: str | Path, *, include_pilot: bool = False) -> dict[str, int]:
        """Every file of exports.zip into a folder (the CSVs, codebook.csv, study.json...); rows per CSV (header
        excluded)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        rows = {}
        with zipfile.ZipFile(io.BytesIO(self.export_zip(study_id, include_pilot=include_pilot))) as archive:
            for name in archive.namelist():
                data = archive.read(name)
                (out / Path(name).name).write_bytes(data)
                if name.endswith(".csv"):
                    rows[name.removesuffix(".csv")] = max(0, data.count(b"\r\n") - 1)
        return rows


# ---------------------------------------------------------------------- scripted teacher


def truth_mask(formula: str, task: str = "dinner") -> int:
    """The clause mask of a ground truth given as a formula (over the task's objects) or, on the dinner table, as
    task1 / task2; ValueError names what is wrong."""
    named = DINNER_TASK_FORMULAS.get(formula) if task == "dinner" else None
    return get_domain(task).clause_space.mask_of_formula(named or formula)


def task_of(objects: Sequence[str] | None) -> str:
    """The learner's task of a study whose objects are these (None or the dinner objects: the dinner table)."""
    return "dinner" if not objects or tuple(objects) == DINNER_OBJECTS else objects_task(tuple(objects))


@dataclass
class TeacherRun:
    """What a scripted teacher did, in order, and what the robot learned."""

    participant_id: int | None = None
    token: str | None = None
    actions: list[dict[str, Any]] = field(default_factory=list)
    final: list[dict[str, Any]] = field(default_factory=list)
    completion_code: str | None = None
    requests: int = 0

    def summary(self) -> dict[str, Any]:
        """JSON summary (the token is left out: it is the participant's secret)."""
        executions = [a for a in self.actions if a["kind"] in ("query", "test")]
        return {"participant_id": self.participant_id, "executions": executions, "final": self.final,
                "map_formula": self.final[-1]["map_formula"] if self.final else None,
                "similarity": self.final[-1]["similarity"] if self.final else None,
                "completion_code": self.completion_code, "n_actions": len(self.actions), "requests": self.requests}


def _guard(state: dict[str, Any]) -> dict[str, Any]:
    return {"task_index": state["task"]["index"], "step_kind": state["step"]["kind"],
            "step_index": state["step"]["index"]}


@dataclass
class StudyKnowledge:
    """What a scripted teacher knows of the study beforehand: the quiz's answers and the attention checks'
    expected answers (from the study definition, given the experimenter token, or from the command line)."""

    quiz_answers: dict[str, int] = field(default_factory=dict)
    attention: dict[str, int] = field(default_factory=dict)
    attention_fail_rate: float = 0.0
    n_tasks: int | None = None
    has_quiz: bool | None = None
    objects: tuple[str, ...] | None = None  # a study with its own objects: their names

    @classmethod
    def of_study(cls, spec: dict[str, Any], *, attention_fail_rate: float = 0.0) -> StudyKnowledge:
        """From a study definition (GET /studies/{id}/spec)."""
        return cls(quiz_answers={q["id"]: q["correct"] for q in spec.get("quiz") or []},
                   attention={i["id"]: i["expected"] for i in spec.get("questionnaire") or []
                              if i.get("kind") == "attention"},
                   attention_fail_rate=attention_fail_rate, n_tasks=len(spec.get("tasks") or []),
                   has_quiz=bool(spec.get("quiz")),
                   objects=tuple(o["name"] for o in spec["objects"]) if spec.get("objects") else None)


def _answers(items: list[dict[str, Any]], rng: np.random.Generator, knows: StudyKnowledge) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        if item["kind"] == "likert5":
            out[item["id"]] = int(rng.integers(3, 6))
        elif item["kind"] == "rating10":
            out[item["id"]] = int(rng.integers(6, 11))
        elif item["kind"] == "attention":
            expected = knows.attention.get(item["id"])
            if expected is None:  # not told the expected answer (it stays on the server): a guess
                out[item["id"]] = int(rng.integers(1, 6))
            elif rng.random() < knows.attention_fail_rate:
                out[item["id"]] = int(rng.choice([v for v in range(1, 6) if v != expected]))
            else:
                out[item["id"]] = int(expected)
        else:
            out[item["id"]] = "=scripted teacher"  # starts like a formula on purpose: exports must escape it
    return out


def cannot_finish(knows: StudyKnowledge, ground_truths: list[str]) -> str | None:
    """Why a scripted teacher could not finish this study (checked before joining), or None."""
    if knows.n_tasks is not None and len(ground_truths) not in (1, knows.n_tasks):
        return (f"the study has {knows.n_tasks} tasks but {len(ground_truths)} ground truths were given; give one "
                "for all tasks or one per task")
    if knows.has_quiz and not knows.quiz_answers:
        return "the study has a comprehension quiz and its answers are unknown; give the experimenter token"
    if knows.n_tasks is not None:  # the study definition is known: its objects (or the dinner table's) too
        return truth_problem(ground_truths, task_of(knows.objects))
    return None


def truth_problem(ground_truths: list[str], task: str) -> str | None:
    """Why a ground truth is not a formula over the task's objects, or None."""
    for formula in ground_truths:
        try:
            truth_mask(formula, task)
        except ValueError as exc:
            return f"--ground-truth {formula!r}: {exc}"
    return None


def session_timeout(state: dict[str, Any], given: float | None) -> float:
    """Seconds a session may take: as given, else three times the server's own estimate (progress.minutes_left,
    which counts the robot's motion at the study's speed), at least 10 minutes."""
    if given is not None:
        return given
    minutes = (state.get("progress") or {}).get("minutes_left") or 10
    return max(600.0, 3 * 60.0 * minutes)


def run_teacher(server: str, study_id: str, ground_truths: list[str], *, noise: float = 0.0, seed: int = 0,
                demo_mode: str = DEFAULT_DEMO_MODE,
                prolific_pid: str | None = None, session_id: str | None = None, poll_seconds: float = 0.02,
                timeout: float | None = None, knows: StudyKnowledge | None = None,
                on_request: Callable[[str, float, int], None] | None = None,
                client: ParticipantClient | None = None, stop_after: int | None = None) -> TeacherRun:
    """Complete a participant session as the simulated teacher (one ground truth per task, or one for all).

    knows: the quiz's and attention checks' answers (StudyKnowledge.of_study); ValueError before joining if the
    study cannot be finished with what is known. demo_mode: how the teacher demonstrates (core.teachers.DEMO_MODES).
    timeout: seconds for the whole session (default: fitted to the server's estimate, session_timeout).
    stop_after: leave after that many actions (to test resuming)."""
    knows = knows or StudyKnowledge()
    problem = cannot_finish(knows, ground_truths)
    if problem is not None:
        raise ValueError(f"not joining: {problem}")
    rng = np.random.default_rng(seed)
    run = TeacherRun()
    counted = on_request

    def count(name: str, seconds: float, status: int) -> None:
        run.requests += 1
        if counted is not None:
            counted(name, seconds, status)

    api = client or ParticipantClient(server, on_request=count)
    api.on_request = count
    state = api.state() if api.token else api.join(study_id, prolific_pid=prolific_pid, session_id=session_id)["state"]
    run.participant_id, run.token = state["participant_id"], api.token
    # The study's objects are the page's (its own, or the dinner table's): the ground truths are formulas over them.
    task = task_of(state.get("objects") if state.get("own_objects") else None)
    problem = truth_problem(ground_truths, task)
    if problem is not None:
        raise ValueError(f"the study's objects are {', '.join(state['objects'])}: {problem}")
    domain = get_domain(task)
    teachers = [SimulatedTeacher(domain, truth_mask(g, task), noise, demo_mode) for g in ground_truths]
    timeout = session_timeout(state, timeout)
    deadline = time.monotonic() + timeout
    while state["stage"] not in ("done", "withdrawn", "screened_out"):
        if time.monotonic() > deadline:
            raise TimeoutError(f"the session did not finish within {timeout} s (stage {state['stage']})")
        if stop_after is not None and len(run.actions) >= stop_after:
            return run
        stage = state["stage"]
        if stage == "consent":
            state = api.consent(state["consent"]["version"])
            run.actions.append({"kind": "consent"})
        elif stage == "instructions":
            state = api.instructions()
            run.actions.append({"kind": "instructions"})
        elif stage == "quiz":
            items = state["quiz"]["items"]
            missing = [q["id"] for q in items if q["id"] not in knows.quiz_answers]
            if missing:
                raise ValueError(f"no answer to quiz item(s) {', '.join(missing)}; give the experimenter token or "
                                 "--quiz-answers")
            state = api.quiz({q["id"]: knows.quiz_answers[q["id"]] for q in items})
            run.actions.append({"kind": "quiz"})
        elif stage == "questionnaire":
            answers = _answers(state["questionnaire"], rng, knows)
            state = api.questionnaire(answers)
            run.actions.append({"kind": "questionnaire", "answers": answers})
        else:
            state = _teach_step(api, state, teachers, rng, run, poll_seconds)
    if state["stage"] == "done":
        run.completion_code = state["completion"]["code"]
        for item in state["completion"]["learned"]:
            mask = teachers[min(item["task_index"], len(teachers) - 1)].truth_mask
            learned = domain.clause_space.mask_of_formula(item["map_formula"])
            run.final.append({**item, "similarity": similarity(domain.clause_space, learned, mask)})
    return run


MAX_POLL_SECONDS = 0.5  # a scripted teacher waiting on the robot reads its state at least this often


def _poll_waits(first: float) -> Iterator[float]:
    """Pauses between reads while waiting on the robot: `first`, doubling up to MAX_POLL_SECONDS."""
    wait = first
    while True:
        yield wait
        wait = min(MAX_POLL_SECONDS, wait * 2)


def _teach_step(api: ParticipantClient, state: dict[str, Any], teachers: list[SimulatedTeacher],
                rng: np.random.Generator, run: TeacherRun, poll_seconds: float) -> dict[str, Any]:
    """One practice trial, demonstration, query or test."""
    task_index, step = state["task"]["index"], state["step"]
    if task_index >= len(teachers) and len(teachers) > 1:
        raise ValueError(f"the study has more than {len(teachers)} tasks; give one --ground-truth per task")
    teacher = teachers[min(task_index, len(teachers) - 1)]
    guard = _guard(state)
    if step["kind"] in ("practice", "demonstration"):
        events = [e for e in teacher.demonstrate(rng).events if e not in state["demonstration"]["placed"]]
        for obj in events:
            state = api.place(obj, guard)
        waits = _poll_waits(poll_seconds)
        while not state["demonstration"].get("settled", True):  # the robot reports the table after its physics
            time.sleep(next(waits))
            state = api.state()
        trace = state["demonstration"]["trace"]
        state = api.finish(guard)
        run.actions.append({"kind": step["kind"], "task_index": task_index, "index": step["index"],
                            "events": events, "trace": trace, "acceptable": True})
        return state
    if state["execution"]["status"] == "not_started":
        state = api.execute(guard)
    waits = _poll_waits(poll_seconds)
    while state["execution"]["status"] != "finished":
        time.sleep(next(waits))
        state = api.state()
    execution = state["execution"]
    trace = [frozenset(labels) for labels in execution["trace"]]
    verdict = teacher.assess(trace, rng)
    state = api.assess(verdict, guard)
    run.actions.append({"kind": step["kind"], "task_index": task_index, "index": step["index"],
                        "events": execution["events"], "trace": execution["trace"], "acceptable": verdict})
    return state
