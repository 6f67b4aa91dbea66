"""Experimenter accounts: roles (owner, experimenter, analyst), per-person API tokens with expiry and revocation, the
dashboard's password login (argon2), and the audit log of every experimenter write (JSON and CSV)."""

from __future__ import annotations

import csv
import io
from datetime import datetime, timedelta, timezone
from typing import Any

import pytest

from .helpers import EXP, bearer, join, make_study
from .conftest import study_spec


def _person(client: Any, name: str, role: str, password: str | None = None) -> str:
    """Create an account as the bootstrap owner and issue its API token; the token."""
    made = client.post("/api/v1/accounts", json={"name": name, "role": role, "password": password}, headers=EXP)
    assert made.status_code == 201, made.text
    issued = client.post(f"/api/v1/accounts/{name}/tokens", json={"label": "laptop", "days": 30}, headers=EXP)
    assert issued.status_code == 201, issued.text
    return issued.json()["token"]


def test_each_role_may_do_what_it_is_for(app_client) -> None:
    study_id = make_study(app_client)
    experimenter = bearer(_person(app_client, "ada", "experimenter"))
    analyst = bearer(_person(app_client, "bo", "analyst"))
    owner = bearer(_person(app_client, "cy", "owner"))

    assert app_client.get("/api/v1/whoami", headers=experimenter).json() == {"name": "ada", "role": "experimenter",
                                                                            "server_key": False}
    # Experimenters run studies and participants, but cannot manage accounts.
    made = app_client.post("/api/v1/studies", json=study_spec(["active"]), headers=experimenter)
    assert made.status_code == 201
    assert app_client.post(f"/api/v1/studies/{made.json()['id']}/open", headers=experimenter).status_code == 200
    refused = app_client.post("/api/v1/accounts", json={"name": "eve", "role": "owner"}, headers=experimenter)
    assert refused.status_code == 403 and "experimenter" in refused.json()["detail"]
    assert app_client.get("/api/v1/accounts", headers=experimenter).status_code == 403
    # Analysts read and export only.
    assert app_client.get(f"/api/v1/studies/{study_id}/participants", headers=analyst).status_code == 200
    assert app_client.get(f"/api/v1/studies/{study_id}/exports/participants.csv", headers=analyst).status_code == 200
    for method, path in (("post", "/api/v1/studies"), ("post", f"/api/v1/studies/{study_id}/close"),
                         ("delete", f"/api/v1/studies/{study_id}/participants/1")):
        kwargs: dict[str, Any] = {"json": study_spec(["active"])} if path == "/api/v1/studies" else {}
        answer = getattr(app_client, method)(path, headers=analyst, **kwargs)
        assert answer.status_code == 403, (method, path, answer.text)
        assert "analyst" in answer.json()["detail"]
    assert app_client.get(f"/api/v1/studies/{study_id}", headers=analyst).json()["status"] == "open"
    # A personal owner manages accounts.
    added = app_client.post("/api/v1/accounts", json={"name": "dee", "role": "analyst"}, headers=owner)
    assert added.status_code == 201
    assert {p["name"] for p in app_client.get("/api/v1/accounts", headers=owner).json()} == {"ada", "bo", "cy", "dee"}


def test_tokens_expire_and_can_be_revoked_and_accounts_disabled(app_client) -> None:
    from sqlalchemy import update

    from tableteach.db.tables import ApiTokenRow

    token = _person(app_client, "ada", "experimenter")
    h = bearer(token)
    assert app_client.get("/api/v1/studies", headers=h).status_code == 200
    records = app_client.get("/api/v1/accounts/all-tokens", headers=EXP).json()
    assert [r["name"] for r in records] == ["ada"] and "token" not in records[0]
    assert app_client.delete(f"/api/v1/accounts/tokens/{records[0]['id']}", headers=EXP).status_code == 200
    gone = app_client.get("/api/v1/studies", headers=h)
    assert gone.status_code == 401 and "revoked" in gone.json()["detail"]

    second = bearer(app_client.post("/api/v1/accounts/ada/tokens", json={"days": 1}, headers=EXP).json()["token"])
    assert app_client.get("/api/v1/studies", headers=second).status_code == 200
    with app_client.ctx.db.write() as s:  # a day later
        s.execute(update(ApiTokenRow).values(expires_at=datetime.now(timezone.utc) - timedelta(seconds=1)))
        s.commit()
    assert app_client.get("/api/v1/studies", headers=second).status_code == 401

    third = bearer(app_client.post("/api/v1/accounts/ada/tokens", json={"days": 1}, headers=EXP).json()["token"])
    assert app_client.post("/api/v1/accounts/ada/disable", headers=EXP).status_code == 200
    assert app_client.get("/api/v1/studies", headers=third).status_code == 401
    assert app_client.post("/api/v1/accounts/ada/tokens", json={"days": 1}, headers=EXP).status_code == 409


def test_bad_account_fields_are_named(app_client) -> None:
    answer = app_client.post("/api/v1/accounts", json={"name": "", "role": "boss", "password": "short"}, headers=EXP)
    assert answer.status_code == 422
    answer = app_client.post("/api/v1/accounts", json={"name": "ok name", "role": "boss", "password": "short"},
                             headers=EXP)
    assert answer.status_code == 422 and {e["field"] for e in answer.json()["errors"]} == {"role", "password"}
    assert app_client.post("/api/v1/accounts/x/tokens", json={"days": 0}, headers=EXP).status_code == 422
    assert app_client.post("/api/v1/accounts/nobody/tokens", json={"days": 1}, headers=EXP).status_code == 404
    _person(app_client, "ada", "analyst")
    assert app_client.post("/api/v1/accounts", json={"name": "ada", "role": "analyst"}, headers=EXP).status_code == 409


def test_the_dashboard_login_checks_an_argon2_password(app_client) -> None:
    from tableteach.db.tables import ExperimenterRow

    _person(app_client, "ada", "experimenter", password="correct horse battery")
    with app_client.ctx.db.read() as s:
        stored = s.query(ExperimenterRow).one().password_hash
    assert stored.startswith("$argon2id$") and "correct horse" not in stored
    logged = app_client.post("/api/v1/login", json={"name": "ada", "password": "correct horse battery"})
    assert logged.status_code == 200 and logged.json()["role"] == "experimenter"
    expires = datetime.fromisoformat(logged.json()["expires_at"])
    assert timedelta(hours=11) < expires - datetime.now(timezone.utc) <= timedelta(hours=12)
    assert app_client.get("/api/v1/whoami", headers=bearer(logged.json()["token"])).json()["name"] == "ada"
    for name, password in (("ada", "wrong password!!"), ("nobody", "correct horse battery")):
        wrong = app_client.post("/api/v1/login", json={"name": name, "password": password})
        assert wrong.status_code == 401 and wrong.json()["detail"] == "wrong name or password"


def test_every_experimenter_write_is_in_the_audit_log_with_who_what_when_where(app_client) -> None:
    before = datetime.now(timezone.utc)
    study_id = make_study(app_client)  # by the server key: create and open
    ada = bearer(_person(app_client, "ada", "experimenter"))
    token, _ = join(app_client, study_id)  # a participant's write: not an experimenter's, not audited
    assert app_client.post(f"/api/v1/studies/{study_id}/close", headers=ada).status_code == 200
    analyst = bearer(_person(app_client, "bo", "analyst"))
    assert app_client.post(f"/api/v1/studies/{study_id}/open", headers=analyst).status_code == 403
    app_client.get(f"/api/v1/studies/{study_id}", headers=ada)  # a read: not audited

    entries = app_client.get("/api/v1/audit", headers=EXP).json()
    seen = [(e["actor"], e["method"], e["path"], e["status"]) for e in reversed(entries)]
    assert seen == [
        ("owner (server key)", "POST", "/api/v1/studies", 201),
        ("owner (server key)", "POST", f"/api/v1/studies/{study_id}/open", 200),
        ("owner (server key)", "POST", "/api/v1/accounts", 201),
        ("owner (server key)", "POST", "/api/v1/accounts/ada/tokens", 201),
        ("ada", "POST", f"/api/v1/studies/{study_id}/close", 200),
        ("owner (server key)", "POST", "/api/v1/accounts", 201),
        ("owner (server key)", "POST", "/api/v1/accounts/bo/tokens", 201),
        ("bo", "POST", f"/api/v1/studies/{study_id}/open", 403),
    ]
    assert all(e["client"] == "testclient" and datetime.fromisoformat(e["at"]) >= before for e in entries)
    assert {e["role"] for e in entries if e["actor"] == "bo"} == {"analyst"}
    # The analyst reads and exports it too.
    exported = app_client.get("/api/v1/audit.csv", headers=analyst)
    assert exported.status_code == 200 and exported.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(exported.text)))
    assert [(r["actor"], r["method"], r["path"], int(r["status"])) for r in rows] == seen


@pytest.mark.parametrize("path", ["/api/v1/audit", "/api/v1/accounts", "/api/v1/whoami"])
def test_the_account_endpoints_need_a_token(app_client, path: str) -> None:
    assert app_client.get(path).status_code == 401
    assert app_client.get(path, headers=bearer("tt_not-a-real-token")).status_code == 401


def _login(client: Any, name: str, password: str) -> dict[str, str]:
    logged = client.post("/api/v1/login", json={"name": name, "password": password})
    assert logged.status_code == 200, logged.text
    return bearer(logged.json()["token"])


def test_a_person_changes_their_own_password_and_their_other_logins_end(app_client) -> None:
    api_token = bearer(_person(app_client, "bo", "analyst", password="correct horse battery"))
    here, elsewhere = (_login(app_client, "bo", "correct horse battery") for _ in range(2))
    url = "/api/v1/password"
    wrong = app_client.post(url, json={"current_password": "not my password", "new_password": "a new long secret"},
                            headers=here)
    assert wrong.status_code == 422 and wrong.json()["errors"] == [
        {"field": "current_password", "message": "is not your current password"}]
    short = app_client.post(url, json={"current_password": "correct horse battery", "new_password": "short"},
                            headers=here)
    assert short.status_code == 422 and short.json()["errors"][0]["field"] == "new_password"
    # An analyst may only read, but may change her own password.
    changed = app_client.post(url, json={"current_password": "correct horse battery",
                                         "new_password": "a new long secret"}, headers=here)
    assert changed.status_code == 200 and changed.json()["ended_logins"] == 1, changed.text
    assert app_client.get("/api/v1/studies", headers=here).status_code == 200  # this login stays
    assert app_client.get("/api/v1/studies", headers=api_token).status_code == 200  # and her API token
    assert app_client.get("/api/v1/studies", headers=elsewhere).status_code == 401  # the other login ended
    assert app_client.post("/api/v1/login", json={"name": "bo", "password": "correct horse battery"}).status_code \
        == 401
    _login(app_client, "bo", "a new long secret")
    # The server key has no password to change.
    refused = app_client.post(url, json={"current_password": "x", "new_password": "a new long secret"}, headers=EXP)
    assert refused.status_code == 409 and "server's experimenter key" in refused.json()["detail"]
    entries = [(e["actor"], e["path"], e["status"]) for e in app_client.get("/api/v1/audit", headers=EXP).json()
               if e["path"] == url]
    assert entries == [("owner (server key)", url, 409), ("bo", url, 200), ("bo", url, 422), ("bo", url, 422)]


def test_the_token_list_shows_dashboard_logins_only_while_they_work(app_client) -> None:
    _person(app_client, "di", "experimenter", password="correct horse battery")
    first = _login(app_client, "di", "correct horse battery")
    listed = [t for t in app_client.get("/api/v1/accounts/all-tokens", headers=EXP).json() if t["name"] == "di"]
    assert sorted(t["label"] for t in listed) == ["dashboard login", "laptop"]
    login_id = next(t["id"] for t in listed if t["label"] == "dashboard login")
    laptop_id = next(t["id"] for t in listed if t["label"] == "laptop")
    for token_id in (login_id, laptop_id):
        assert app_client.delete(f"/api/v1/accounts/tokens/{token_id}", headers=EXP).status_code == 200
    assert app_client.get("/api/v1/studies", headers=first).status_code == 401
    second = _login(app_client, "di", "correct horse battery")
    _login(app_client, "di", "correct horse battery")
    listed = [t for t in app_client.get("/api/v1/accounts/all-tokens", headers=EXP).json() if t["name"] == "di"]
    # the revoked login is not listed; the two live ones and the revoked labelled token are
    assert sorted((t["label"], t["revoked_at"] is None) for t in listed) == [
        ("dashboard login", True), ("dashboard login", True), ("laptop", False)]
    assert login_id not in {t["id"] for t in listed}
    assert app_client.get("/api/v1/studies", headers=second).status_code == 200


def test_an_owner_sets_a_forgotten_password(app_client) -> None:
    _person(app_client, "ada", "experimenter")  # no password: API token only
    assert app_client.post("/api/v1/login", json={"name": "ada", "password": "anything at all"}).status_code == 401
    set_ = app_client.post("/api/v1/accounts/ada/password", json={"password": "chosen by the owner"}, headers=EXP)
    assert set_.status_code == 200 and set_.json()["has_password"] is True
    ada = _login(app_client, "ada", "chosen by the owner")
    again = app_client.post("/api/v1/accounts/ada/password", json={"password": "a second new one"}, headers=EXP)
    assert again.json()["ended_logins"] == 1 and app_client.get("/api/v1/studies", headers=ada).status_code == 401
    assert app_client.post("/api/v1/accounts/ada/password", json={"password": "short"},
                           headers=EXP).json()["errors"][0]["field"] == "password"
    assert app_client.post("/api/v1/accounts/nobody/password", json={"password": "long enough pass"},
                           headers=EXP).status_code == 404
    experimenter = bearer(_person(app_client, "cy", "experimenter"))
    assert app_client.post("/api/v1/accounts/ada/password", json={"password": "long enough pass"},
                           headers=experimenter).status_code == 403


def test_erasures_and_assistance_name_the_acting_person(app_client) -> None:
    study_id = make_study(app_client, pilot=True)
    ada = bearer(_person(app_client, "ada", "experimenter"))
    first, second = join(app_client, study_id)[1]["participant_id"], join(app_client, study_id)[1]["participant_id"]
    assert app_client.delete(f"/api/v1/studies/{study_id}/participants/{first}", headers=ada).status_code == 204
    assert app_client.post(f"/api/v1/studies/{study_id}/pilot/reset", headers=EXP).status_code == 200
    log = app_client.get(f"/api/v1/studies/{study_id}/erasures", headers=ada).json()
    assert [(e["participant_id"], e["erased_by"], e["reason"]) for e in log] == [
        (first, "ada", "erasure"), (second, "owner (server key)", "pilot_reset")]
