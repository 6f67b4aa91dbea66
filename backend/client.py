"""Python client of the study server (httpx) and a scripted teacher that completes a session over HTTP.

The scripted teacher is the paper's simulated teacher (tableteach.core.teachers) speaking the same
participant API as the browser page: it demonstrates by placing objects one at a time, lets the
robot execute each query and test, and assesses the trace the server reports.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from .core.domain import DINNER_TASK_FORMULAS, get_domain
from .core.metrics import similarity
from .core.teachers import SimulatedTeacher

RETRIES = 4


class ApiError(Exception):
    """The server refused a request: status, its message and (for 409) the current state."""

    def __init__(self, status: int, detail: str, state: dict[str, Any] | None = None) -> None:
        super().__init__(f"HTTP {status}: {detail}")
        self.status, self.detail, self.state = status, detail, state


class _Base:
    """Shared HTTP plumbing: JSON, error decoding, retries of idempotent attempts on network errors."""

    def __init__(self, server: str, *, token: str | None = None, timeout: float = 30.0,
                 on_request: Callable[[str, float, int], None] | None = None) -> None:
        self.server = server.rstrip("/")
        self.http = httpx.Client(base_url=self.server, timeout=timeout)
        self.token = token
        self.on_request = on_request

    def close(self) -> None:
        """Close the connection pool."""
        self.http.close()

    def _request(self, method: str, path: str, *, json: Any = None, key: str | None = None) -> httpx.Response:
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        if key is not None:
            headers["Idempotency-Key"] = key
        for attempt in range(RETRIES):
            started = time.perf_counter()
            try:
                response = self.http.request(method, path, json=json, headers=headers)
            except httpx.TransportError:
                # Safe to resend: GETs change nothing and POSTs carry the same Idempotency-Key.
                if attempt == RETRIES - 1 or (method != "GET" and key is None):
                    raise
                time.sleep(0.2 * 2**attempt)
                continue
            if self.on_request is not None:
                self.on_request(f"{method} {path}", time.perf_counter() - started, response.status_code)
            if response.status_code >= 400:
                try:
                    body = response.json()
                except ValueError:
                    body = {"detail": response.text}
                raise ApiError(response.status_code, str(body.get("detail")), body.get("state"))
            return response
        raise AssertionError("unreachable")

    def _json(self, method: str, path: str, body: Any = None, *, idempotent: bool = True) -> Any:
        key = str(uuid.uuid4()) if method == "POST" and idempotent else None
        return self._request(method, path, json=body, key=key).json()


class ParticipantClient(_Base):
    """The participant API (the token comes from join())."""

    def join(self, study_id: str, *, prolific_pid: str | None = None, session_id: str | None = None) -> dict[str, Any]:
        """Join a study; remembers the token. Rejoining with a prolific_pid needs the same session_id (or client)."""
        body = {k: v for k, v in (("prolific_pid", prolific_pid), ("session_id", session_id)) if v}
        out = self._request("POST", f"/api/v1/studies/{study_id}/join", json=body).json()
        self.token = out["token"]
        return out

    def state(self) -> dict[str, Any]:
        """The current state."""
        return self._json("GET", "/api/v1/me")

    def consent(self, version: str, agree: bool = True) -> dict[str, Any]:
        """Agree to the consent text of this version."""
        return self._json("POST", "/api/v1/me/consent", {"agree": agree, "consent_version": version})

    def instructions(self) -> dict[str, Any]:
        """Mark the instructions as read."""
        return self._json("POST", "/api/v1/me/instructions")

    def place(self, obj: str, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Place an object during a demonstration."""
        return self._json("POST", "/api/v1/me/placements", {"object": obj, **(guard or {})})

    def finish(self, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """End the demonstration."""
        return self._json("POST", "/api/v1/me/demonstration/finish", guard or {})

    def execute(self, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Let the robot carry out the current query or test."""
        return self._json("POST", "/api/v1/me/execution", guard or {})

    def assess(self, acceptable: bool | None, guard: dict[str, Any] | None = None) -> dict[str, Any]:
        """Judge the robot's finished execution."""
        return self._json("POST", "/api/v1/me/assessment", {"acceptable": acceptable, **(guard or {})})

    def questionnaire(self, answers: dict[str, Any]) -> dict[str, Any]:
        """Answer the questionnaire."""
        return self._json("POST", "/api/v1/me/questionnaire", {"answers": answers})


class ExperimenterClient(_Base):
    """The experimenter API (token: the server's experimenter secret)."""

    def create_study(self, spec: dict[str, Any]) -> dict[str, Any]:
        """Create a study (draft)."""
        return self._json("POST", "/api/v1/studies", spec, idempotent=False)

    def open_study(self, study_id: str) -> dict[str, Any]:
        """Open a study."""
        return self._json("POST", f"/api/v1/studies/{study_id}/open", idempotent=False)

    def close_study(self, study_id: str) -> dict[str, Any]:
        """Close a study."""
        return self._json("POST", f"/api/v1/studies/{study_id}/close", idempotent=False)

    def participants(self, study_id: str) -> list[dict[str, Any]]:
        """Participants with live status."""
        return self._json("GET", f"/api/v1/studies/{study_id}/participants")

    def belief(self, study_id: str, participant_id: int) -> dict[str, Any]:
        """A participant's belief summary."""
        return self._json("GET", f"/api/v1/studies/{study_id}/participants/{participant_id}/belief")

    def export(self, study_id: str, name: str, *, include_pilot: bool = False) -> str:
        """One CSV export as text (pilot participants only if include_pilot)."""
        query = "?include_pilot=true" if include_pilot else ""
        return self._request("GET", f"/api/v1/studies/{study_id}/exports/{name}.csv{query}").text

    def export_all(self, study_id: str, out_dir: str | Path, *, include_pilot: bool = False) -> dict[str, int]:
        """Download every CSV export and the codebook into a folder; rows per file (header excluded)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        rows = {}
        for name in ("participants", "events", "steps", "beliefs", "questionnaire", "codebook"):
            text = self.export(study_id, name, include_pilot=include_pilot)
            (out / f"{name}.csv").write_text(text, encoding="utf-8")
            rows[name] = max(0, text.count("\r\n") - 1)
        return rows


# ---------------------------------------------------------------------- scripted teacher


def truth_mask(formula: str) -> int:
    """The clause mask of a ground truth given as a formula or as task1 / task2."""
    return get_domain("dinner").clause_space.mask_of_formula(DINNER_TASK_FORMULAS.get(formula, formula))


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


def _answers(items: list[dict[str, Any]], rng: np.random.Generator) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        if item["kind"] == "likert5":
            out[item["id"]] = int(rng.integers(3, 6))
        elif item["kind"] == "rating10":
            out[item["id"]] = int(rng.integers(6, 11))
        elif item["kind"] == "attention":
            out[item["id"]] = int(rng.integers(1, 6))  # the expected answer stays on the server
        else:
            out[item["id"]] = "=scripted teacher"  # starts like a formula on purpose: exports must escape it
    return out


def run_teacher(server: str, study_id: str, ground_truths: list[str], *, noise: float = 0.0, seed: int = 0,
                prolific_pid: str | None = None, session_id: str | None = None, poll_seconds: float = 0.02,
                timeout: float = 300.0,
                on_request: Callable[[str, float, int], None] | None = None,
                client: ParticipantClient | None = None, stop_after: int | None = None) -> TeacherRun:
    """Complete a participant session as the simulated teacher (one ground truth per task, or one for all).

    stop_after: leave after that many actions (to test resuming); the run is then unfinished."""
    domain = get_domain("dinner")
    teachers = [SimulatedTeacher(domain, truth_mask(g), noise) for g in ground_truths]
    rng = np.random.default_rng(seed)
    run = TeacherRun()
    counted = on_request

    def count(name: str, seconds: float, status: int) -> None:
        run.requests += 1
        if counted is not None:
            counted(name, seconds, status)

    api = client or ParticipantClient(server, on_request=count)
    api.on_request = count
    deadline = time.monotonic() + timeout
    state = api.state() if api.token else api.join(study_id, prolific_pid=prolific_pid, session_id=session_id)["state"]
    run.participant_id, run.token = state["participant_id"], api.token
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
            raise ValueError("this study has a comprehension quiz; the scripted teacher does not know its answers")
        elif stage == "questionnaire":
            answers = _answers(state["questionnaire"], rng)
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
        while not state["demonstration"].get("settled", True):  # the robot reports the table after its physics
            time.sleep(poll_seconds)
            state = api.state()
        trace = state["demonstration"]["trace"]
        state = api.finish(guard)
        run.actions.append({"kind": step["kind"], "task_index": task_index, "index": step["index"],
                            "events": events, "trace": trace, "acceptable": True})
        return state
    if state["execution"]["status"] == "not_started":
        state = api.execute(guard)
    while state["execution"]["status"] != "finished":
        time.sleep(poll_seconds)
        state = api.state()
    execution = state["execution"]
    trace = [frozenset(labels) for labels in execution["trace"]]
    verdict = teacher.assess(trace, rng)
    state = api.assess(verdict, guard)
    run.actions.append({"kind": step["kind"], "task_index": task_index, "index": step["index"],
                        "events": execution["events"], "trace": execution["trace"], "acceptable": verdict})
    return state
