"""The dashboard's password login and its audit log page, in Debian's Chromium at a laptop's and a phone's size."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.web.conftest import (  # noqa: F401  (server_factory is a fixture used by name)
    EXPERIMENTER_TOKEN,
    open_study,
    server_factory,
    study_spec,
)

OWNER = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}


@pytest.mark.browser
@pytest.mark.parametrize("viewport", [{"width": 1366, "height": 768}, {"width": 390, "height": 844}])
def test_a_person_logs_in_with_a_password_and_reads_the_audit_log(
    server_factory: Any, browser_page: Any, viewport: dict[str, int], tmp_path: Path  # noqa: F811
) -> None:
    server = server_factory()
    made = httpx.post(f"{server.url}/api/v1/accounts", headers=OWNER, timeout=10,
                      json={"name": "ada", "role": "analyst", "password": "correct horse battery"})
    assert made.status_code == 201, made.text
    study_id = open_study(server.url, study_spec(["active"], name="Audited study"))
    page = browser_page
    page.set_viewport_size(viewport)
    page.goto(f"{server.url}/dashboard")
    page.fill("#login-name", "ada")
    page.fill("#login-password", "not her password")
    page.click("#password-login button[type=submit]")
    page.wait_for_selector("#login-message .error")
    assert "wrong name or password" in page.text_content("#login-message .error")
    shots = os.environ.get("TABLETEACH_SCREENSHOTS")
    if shots:
        page.screenshot(path=f"{shots}/login-{viewport['width']}.png", full_page=True)

    page.fill("#login-password", "correct horse battery")
    page.click("#password-login button[type=submit]")
    page.wait_for_selector("#studies a:has-text('Audited study')")
    page.click("#audit-link")
    table = page.locator("#audit")
    table.wait_for()
    text = table.text_content()
    assert f"POST /api/v1/studies/{study_id}/open" in text and "owner (server key)" in text
    assert "POST /api/v1/login" in text and "ada" in text and "analyst" in text
    if shots:
        page.screenshot(path=f"{shots}/audit-{viewport['width']}.png", full_page=True)
    # The analyst's session token is hers: a write with it is refused (and audited).
    token = page.evaluate("sessionStorage.getItem('tableteach.experimenterToken')")
    refused = httpx.post(f"{server.url}/api/v1/studies/{study_id}/close", headers={"Authorization": f"Bearer {token}"})
    assert refused.status_code == 403


@pytest.mark.browser
def test_an_owner_manages_accounts_and_a_person_changes_her_password(
    server_factory: Any, browser_page: Any  # noqa: F811
) -> None:
    from tests.browser.accessibility import assert_accessible
    from tests.browser.test_dashboard import log_in

    server = server_factory()
    page = browser_page
    page.set_viewport_size({"width": 1366, "height": 768})
    log_in(page, server.url, EXPERIMENTER_TOKEN)
    page.wait_for_selector("#me:has-text('owner (server key) (owner)')")
    page.click("#accounts-link")
    page.wait_for_selector("#people-empty")

    # A refused field is named next to it; then the person is added.
    page.fill("#new-person-name", "ada")
    page.select_option("#new-person-role", "experimenter")
    page.fill("#new-person-password", "short")
    page.evaluate("document.getElementById('new-person-password').removeAttribute('minlength')")  # the server's check
    page.click("#add-person button[type=submit]")
    page.wait_for_selector("[data-error-for='password']:not(:empty)")
    assert "at least 12 characters" in page.text_content("#add-person [data-error-for='password']")
    page.fill("#new-person-password", "correct horse battery")
    page.click("#add-person button[type=submit]")
    page.wait_for_selector("#people tr[data-person='ada']")
    assert "experimenter" in page.text_content("#people tr[data-person='ada']")

    # A token for her, shown once, valid for the days asked; revoking it stops it at once.
    page.select_option("#token-person", "ada")
    page.fill("#token-label", "laptop script")
    page.fill("#token-days", "30")
    page.click("#issue-token button[type=submit]")
    page.wait_for_selector("#new-token")
    token = page.input_value("#new-token")
    assert token.startswith("tt_")
    h = {"Authorization": f"Bearer {token}"}
    assert httpx.get(f"{server.url}/api/v1/whoami", headers=h).json()["name"] == "ada"
    record = httpx.get(f"{server.url}/api/v1/accounts/all-tokens", headers=OWNER).json()[0]
    expires = record["expires_at"][:10]
    row = page.locator(f"#tokens tr[data-token='{record['id']}']")
    assert "laptop script" in row.text_content() and expires in row.text_content() and "active" in row.text_content()
    assert_accessible(page, "accounts (laptop)")
    shots = os.environ.get("TABLETEACH_SCREENSHOTS")
    if shots:
        page.screenshot(path=f"{shots}/accounts-1366.png", full_page=True)
    page.once("dialog", lambda dialog: dialog.accept())
    row.locator("button[data-revoke]").click()
    page.wait_for_selector(f"#tokens tr[data-token='{record['id']}'] .pill:has-text('revoked')")
    assert httpx.get(f"{server.url}/api/v1/studies", headers=h).status_code == 401

    # She logs in with her password; her own page changes it (checked there and on the server).
    page.click("#logout")
    page.fill("#login-name", "ada")
    page.fill("#login-password", "correct horse battery")
    page.click("#password-login button[type=submit]")
    page.wait_for_selector("#me:has-text('ada (experimenter)')")
    page.wait_for_selector("#studies, .card.muted")
    assert page.locator("#accounts-link").count() == 0  # not an owner
    page.click("#me")
    page.wait_for_selector("#change-password")
    assert_accessible(page, "your account (laptop)")
    page.fill("#current-password", "not my password")
    page.fill("#new-password", "a new long secret")
    page.fill("#repeat-password", "a new long secret")
    page.click("#change-password button[type=submit]")
    page.wait_for_selector("[data-error-for='current_password']:not(:empty)")
    assert page.text_content("[data-error-for='current_password']") == "is not your current password"
    page.fill("#current-password", "correct horse battery")
    page.fill("#repeat-password", "a new long secrets")
    page.click("#change-password button[type=submit]")
    page.wait_for_selector("[data-error-for='repeat_password']:not(:empty)")
    page.fill("#repeat-password", "a new long secret")
    page.click("#change-password button[type=submit]")
    page.wait_for_selector("#password-message .ok")
    assert "Your password is changed" in page.text_content("#password-message")
    if shots:
        page.screenshot(path=f"{shots}/account-1366.png", full_page=True)
    old = httpx.post(f"{server.url}/api/v1/login", json={"name": "ada", "password": "correct horse battery"})
    assert old.status_code == 401
    new = httpx.post(f"{server.url}/api/v1/login", json={"name": "ada", "password": "a new long secret"})
    assert new.status_code == 200
    audit = httpx.get(f"{server.url}/api/v1/audit", headers=OWNER).json()
    assert [(e["actor"], e["status"]) for e in audit if e["path"] == "/api/v1/password"] == [("ada", 200), ("ada", 422)]

    # Both pages at a phone's size.
    page.set_viewport_size({"width": 390, "height": 844})
    page.reload()
    page.wait_for_selector("#change-password")
    assert_accessible(page, "your account (phone)")
    page.click("#logout")
    log_in(page, server.url, EXPERIMENTER_TOKEN)
    page.wait_for_selector("#accounts-link")
    page.goto(f"{server.url}/dashboard#/accounts")
    page.wait_for_selector("#tokens")
    assert_accessible(page, "accounts (phone)")
    if shots:
        page.screenshot(path=f"{shots}/accounts-390.png", full_page=True)
    page.goto(f"{server.url}/dashboard#/account")
    page.wait_for_selector("#server-key-note")
    assert_accessible(page, "the server key's account page (phone)")
