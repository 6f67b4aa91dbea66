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
