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

    assert app_client.get("/api/v1/whoami", headers=experimenter).json() == {"name": "ada", "role": "experimenter"}
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
