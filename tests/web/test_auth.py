"""Participants reach only their own session; experimenter endpoints need the experimenter secret."""

from __future__ import annotations

import pytest
from pydantic import SecretStr

from tableteach.config import Settings
from tableteach.web.app import create_app
from tableteach.web.auth import SecretChecker, experimenter_checker, generate_key, hash_secret

from .conftest import EXPERIMENTER_TOKEN
from .helpers import EXP, bearer, make_study, to_teaching

EXPERIMENTER_GETS = ["/api/v1/studies", "/api/v1/studies/{s}", "/api/v1/studies/{s}/participants",
                     "/api/v1/studies/{s}/participants/1/belief", "/api/v1/studies/{s}/exports/events.csv"]


def test_a_participant_token_opens_only_its_own_session(app_client) -> None:
    study = make_study(app_client)
    alice, _ = to_teaching(app_client, study)
    bob, _ = to_teaching(app_client, study)
    app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(alice))
    a = app_client.get("/api/v1/me", headers=bearer(alice)).json()
    b = app_client.get("/api/v1/me", headers=bearer(bob)).json()
    assert a["participant_id"] != b["participant_id"]
    assert a["demonstration"]["placed"] == ["bowl"] and b["demonstration"]["placed"] == []
    assert a["token"] == alice and b["token"] == bob


@pytest.mark.parametrize("path", EXPERIMENTER_GETS)
def test_participants_and_strangers_cannot_use_experimenter_endpoints(app_client, path: str) -> None:
    study = make_study(app_client)
    token, _ = to_teaching(app_client, study)
    url = path.format(s=study)
    for headers in ({}, bearer(token), bearer("wrong-" + EXPERIMENTER_TOKEN), {"Authorization": "Basic eDp5"}):
        response = app_client.get(url, headers=headers)
        assert response.status_code == 401, (url, headers, response.text)
        assert "experimenter" in response.json()["detail"]
    assert app_client.get(url, headers=EXP).status_code == 200
    for action in ("open", "close"):
        assert app_client.post(f"/api/v1/studies/{study}/{action}", headers=bearer(token)).status_code == 401
    assert app_client.post("/api/v1/studies", json={"tasks": [{"key": "task1"}]},
                           headers=bearer(token)).status_code == 401


def test_participant_endpoints_need_a_known_token(app_client) -> None:
    for headers in ({}, bearer("not-a-token"), EXP):
        response = app_client.get("/api/v1/me", headers=headers)
        assert response.status_code == 401
        assert "token" in response.json()["detail"]
    assert app_client.get("/p/not-a-token").status_code == 404


def test_refuses_missing_or_weak_secrets_outside_dev_mode(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'a.db'}"
    with pytest.raises(ValueError, match="TABLETEACH_EXPERIMENTER_TOKEN"):
        create_app(Settings(database_url=url))
    with pytest.raises(ValueError, match="too weak"):
        create_app(Settings(database_url=url, experimenter_token=SecretStr("changeme")))
    checker, generated = experimenter_checker(Settings(database_url=url, dev_mode=True, data_dir=tmp_path / "data"))
    assert generated is not None and generated.startswith("dev-") and checker.check(generated)
    assert not checker.check("dev-guess")


def test_dev_mode_keeps_its_token_across_restarts_under_the_data_folder(tmp_path) -> None:
    url = f"sqlite:///{tmp_path / 'a.db'}"
    first = experimenter_checker(Settings(database_url=url, dev_mode=True, data_dir=tmp_path / "data"))[1]
    again = experimenter_checker(Settings(database_url=url, dev_mode=True, data_dir=tmp_path / "data"))[1]
    other = experimenter_checker(Settings(database_url=url, dev_mode=True, data_dir=tmp_path / "elsewhere"))[1]
    assert first == again and first != other
    path = tmp_path / "data" / "dev-experimenter-token"
    assert path.read_text().strip() == first and path.stat().st_mode & 0o077 == 0
    # Production never uses it: a configured secret wins.
    assert experimenter_checker(Settings(database_url=url, experimenter_token=SecretStr(generate_key()),
                                         data_dir=tmp_path / "data"))[1] is None


def test_a_stored_hash_works_and_the_secret_itself_is_not_needed() -> None:
    stored = hash_secret("a long enough experimenter secret")
    assert "a long enough" not in stored
    checker, generated = experimenter_checker(Settings(experimenter_token_hash=stored))
    assert generated is None
    assert checker.check("a long enough experimenter secret") and checker.check("a long enough experimenter secret")
    assert not checker.check("a long enough experimenter secreT")
    with pytest.raises(ValueError, match="sha256"):
        SecretChecker("sha1$abc")
