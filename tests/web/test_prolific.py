"""Reconciliation with Prolific: its submissions export uploaded to a study, mismatches flagged per Prolific id,
a bonus file in its bulk-bonus format, and the optional API client against a fake following its documented
endpoints."""

from __future__ import annotations

import json
from typing import Any

import httpx
import pytest

from tableteach.prolific_api import ProlificApi, ProlificError, submissions_csv

from .helpers import EXP, bearer, join, make_study
from .test_study_ops import SHORT, finish

CSV_HEADERS = {**EXP, "Content-Type": "text/csv"}


def _participant(client: Any, study: str, pid: str, *, finish_it: bool = False, decline: bool = False) -> int:
    if finish_it:
        from .helpers import demonstrate

        token, state = join(client, study, prolific_pid=pid, session_id=f"S-{pid}")
        h = bearer(token)
        client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=h)
        state = client.post("/api/v1/me/instructions", headers=h).json()
        while state["stage"] == "task":
            state = demonstrate(client, token, ["dinner_plate", "bowl"])
        client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4, "overall": 7}}, headers=h)
        return state["participant_id"]
    token, state = join(client, study, prolific_pid=pid, session_id=f"S-{pid}")
    if decline:
        client.post("/api/v1/me/consent", json={"agree": False, "consent_version": "1"}, headers=bearer(token))
    return state["participant_id"]


def test_uploaded_submissions_are_reconciled_and_mismatches_flagged(app_client) -> None:
    study = make_study(app_client, completion_code="DONE1", declined_consent_code="NOPE2", **SHORT)
    _participant(app_client, study, "P_OK", finish_it=True)
    _participant(app_client, study, "P_RETURNED", finish_it=True)
    _participant(app_client, study, "P_DECLINED", decline=True)
    _participant(app_client, study, "P_NOT_ON_PROLIFIC", finish_it=True)
    export = ("Submission id,Participant id,Status,Started at,Completed at,Completion code\n"
              "s1,P_OK,APPROVED,2026-12-01 10:00,2026-12-01 10:20,DONE1\n"
              "s2,P_RETURNED,RETURNED,2026-12-01 10:00,,\n"
              "s3,P_DECLINED,APPROVED,2026-12-01 10:00,2026-12-01 10:01,NOPE2\n"
              "s4,P_STRANGER,AWAITING REVIEW,2026-12-01 10:00,2026-12-01 10:30,DONE1\n")
    r = app_client.put(f"/api/v1/studies/{study}/prolific/submissions", content=export, headers=CSV_HEADERS)
    assert r.status_code == 200 and r.json()["n_submissions"] == 4, r.text
    table = app_client.get(f"/api/v1/studies/{study}/prolific/reconciliation", headers=EXP).json()
    rows = {row["prolific_pid"]: row for row in table["rows"]}
    assert rows["P_OK"]["mismatch"] is None and rows["P_OK"]["outcome"] == "completed"
    assert rows["P_RETURNED"]["mismatch"] == "returned on Prolific but finished here"
    assert rows["P_DECLINED"]["mismatch"] == "approved on Prolific but declined consent here"
    assert rows["P_STRANGER"]["mismatch"].startswith("unknown here")
    assert rows["P_NOT_ON_PROLIFIC"]["mismatch"].startswith("unknown on Prolific")
    assert table["n_mismatches"] == 4


def test_a_malformed_export_names_the_row_and_column_and_keeps_the_earlier_upload(app_client) -> None:
    study = make_study(app_client, **SHORT)
    url = f"/api/v1/studies/{study}/prolific/submissions"
    good = "Participant id,Status\nP1,APPROVED\n"
    assert app_client.put(url, content=good, headers=CSV_HEADERS).status_code == 200
    bad = "Submission id,Participant id,Status\ns1,P1,APPROVED\ns2,P 2,APPROVED\ns3,P3,DONE\ns4,P1,RETURNED\n"
    r = app_client.put(url, content=bad, headers=CSV_HEADERS)
    assert r.status_code == 422
    fields = {e["field"]: e["message"] for e in r.json()["errors"]}
    assert fields["row 3, column Participant id"] == '"P 2" is not a Prolific participant id'
    assert fields["row 4, column Status"].startswith('"DONE" is not a Prolific status; expected one of ACTIVE')
    assert fields["row 5, column Participant id"] == "P1 is already on row 2"
    r = app_client.put(url, content="Name,Age\nx,1\n", headers=CSV_HEADERS)
    assert r.status_code == 422 and "Participant id or Status" in r.json()["errors"][0]["message"]
    assert app_client.put(url, content=b"\xff\xfe", headers=CSV_HEADERS).status_code == 422
    table = app_client.get(f"/api/v1/studies/{study}/prolific/reconciliation", headers=EXP).json()
    assert [row["prolific_pid"] for row in table["rows"]] == ["P1"]  # the good upload is still there
    assert app_client.put("/api/v1/studies/nope/prolific/submissions", content=good,
                          headers=CSV_HEADERS).status_code == 404


def test_the_bonus_file_follows_the_rule_in_prolifics_bulk_format(app_client) -> None:
    study = make_study(app_client, **SHORT)
    _participant(app_client, study, "P_DONE", finish_it=True)
    _participant(app_client, study, "P_DECLINED", decline=True)
    finish(app_client, study)  # no Prolific id: nothing to pay it with
    url = f"/api/v1/studies/{study}/prolific"
    assert app_client.get(f"{url}/bonuses.csv", headers=EXP).status_code == 422  # no rule yet
    r = app_client.put(f"{url}/bonus-rule", json={"amounts": {"completed": 1.5, "declined_consent": 0}},
                       headers=EXP)
    assert r.status_code == 200 and r.json()["amounts"] == {"completed": "1.50", "declined_consent": "0.00"}
    assert app_client.get(f"{url}/bonuses.csv", headers=EXP).text == "P_DONE,1.50\n"
    for bad, field in (({"finished": 1}, "amounts.finished"), ({"completed": 500}, "amounts.completed"),
                       ({"completed": "lots"}, "amounts.completed"), ({"timeout": -1}, "amounts.timeout")):
        r = app_client.put(f"{url}/bonus-rule", json={"amounts": bad}, headers=EXP)
        assert r.status_code == 422 and r.json()["errors"][0]["field"] == field, r.text


def _fake_prolific(calls: list[tuple[str, str, Any]]) -> httpx.MockTransport:
    """Prolific's documented endpoints: paginated submissions, bonus set-up and payment, Token auth."""
    pages = {None: ({"id": "s1", "participant_id": "P_A", "status": "APPROVED", "entered_code": "DONE1"},
                    {"id": "s2", "participant_id": "P_B", "status": "RETURNED", "entered_code": None}),
             "2": ({"id": "s3", "participant_id": "P_C", "status": "AWAITING_REVIEW", "entered_code": "DONE1"},)}

    def handler(request: httpx.Request) -> httpx.Response:
        if request.headers.get("Authorization") != "Token secret-token":
            return httpx.Response(401, json={"error": "unauthorised"})
        body = json.loads(request.content) if request.content else None
        calls.append((request.method, request.url.path, body))
        if request.url.path == "/api/v1/submissions/" and request.method == "GET":
            page = request.url.params.get("page")
            if page is None and request.url.params.get("study") != "PROLIFIC_STUDY":
                return httpx.Response(404, json={"error": "no such study"})
            nxt = {"href": "https://api.prolific.com/api/v1/submissions/?study=PROLIFIC_STUDY&page=2"} \
                if page is None else None
            return httpx.Response(200, json={"results": list(pages[page]), "_links": {"next": nxt}})
        if request.url.path == "/api/v1/submissions/bonus-payments/":
            return httpx.Response(201, json={"id": "bulk-1", "study": body["study_id"]})
        if request.url.path == "/api/v1/bulk-bonus-payments/bulk-1/pay/":
            return httpx.Response(202, json={})
        return httpx.Response(404, json={"error": "not found"})

    return httpx.MockTransport(handler)


def test_the_prolific_api_client_reads_submissions_and_pays_bonuses_on_a_fake(app_client, monkeypatch) -> None:
    calls: list[tuple[str, str, Any]] = []
    monkeypatch.setenv("TABLETEACH_PROLIFIC_TOKEN", "secret-token")
    api = ProlificApi(transport=_fake_prolific(calls))
    rows = api.submissions("PROLIFIC_STUDY")
    assert [r["participant_id"] for r in rows] == ["P_A", "P_B", "P_C"]
    study = make_study(app_client, **SHORT)
    r = app_client.put(f"/api/v1/studies/{study}/prolific/submissions", content=submissions_csv(rows),
                       headers=CSV_HEADERS)
    assert r.status_code == 200 and r.json()["n_submissions"] == 3, r.text
    statuses = {row["prolific_pid"]: row["prolific_status"] for row in app_client.get(
        f"/api/v1/studies/{study}/prolific/reconciliation", headers=EXP).json()["rows"]}
    assert statuses == {"P_A": "APPROVED", "P_B": "RETURNED", "P_C": "AWAITING REVIEW"}
    bulk = api.set_up_bonuses("PROLIFIC_STUDY", [("P_A", "1.50")])
    api.pay_bonuses(bulk)
    assert calls[-2] == ("POST", "/api/v1/submissions/bonus-payments/",
                         {"study_id": "PROLIFIC_STUDY", "csv_bonuses": "P_A,1.50\n"})
    assert calls[-1][:2] == ("POST", "/api/v1/bulk-bonus-payments/bulk-1/pay/")
    with pytest.raises(ProlificError, match="404"):
        api.submissions("OTHER")
    monkeypatch.delenv("TABLETEACH_PROLIFIC_TOKEN")
    with pytest.raises(ProlificError, match="TABLETEACH_PROLIFIC_TOKEN"):
        ProlificApi()
