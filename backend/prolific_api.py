"""An optional client of Prolific's API (httpx) for reconciliation: list a study's submissions and set up and pay
bulk bonuses. The token comes from the environment (TABLETEACH_PROLIFIC_TOKEN), never from a file in the repo.

Endpoints as Prolific documents them: GET /api/v1/submissions/?study=ID (paginated, `_links.next.href`),
POST /api/v1/submissions/bonus-payments/ {study_id, csv_bonuses} and POST /api/v1/bulk-bonus-payments/ID/pay/;
requests carry "Authorization: Token <token>".
"""

from __future__ import annotations

import csv
import io
import os
from typing import Any

import httpx

API = "https://api.prolific.com"
TOKEN_VARIABLE = "TABLETEACH_PROLIFIC_TOKEN"
MAX_PAGES = 1000


class ProlificError(Exception):
    """Prolific refused a request or answered something unexpected."""


class ProlificApi:
    """Prolific's API with the researcher's token."""

    def __init__(self, token: str | None = None, *, base_url: str = API, transport: httpx.BaseTransport | None = None,
                 timeout: float = 30.0) -> None:
        token = token or os.environ.get(TOKEN_VARIABLE)
        if not token:
            raise ProlificError(f"no Prolific API token: set {TOKEN_VARIABLE} (Prolific: Settings -> API tokens)")
        self.http = httpx.Client(base_url=base_url, timeout=timeout, transport=transport,
                                 headers={"Authorization": f"Token {token}"})

    def close(self) -> None:
        """Close the connection pool."""
        self.http.close()

    def _call(self, method: str, url: str, **kwargs: Any) -> Any:
        response = self.http.request(method, url, **kwargs)
        if response.status_code >= 400:
            raise ProlificError(f"Prolific answered {response.status_code} to {method} {url}: {response.text[:300]}")
        return response.json() if response.content else None

    def submissions(self, study_id: str) -> list[dict[str, Any]]:
        """Every submission of a Prolific study: {participant_id, status, submission_id, entered_code}."""
        out: list[dict[str, Any]] = []
        url: str | None = "/api/v1/submissions/"
        params: dict[str, Any] | None = {"study": study_id, "page_size": 200}
        for _ in range(MAX_PAGES):
            if url is None:
                return out
            page = self._call("GET", url, params=params)
            for item in page.get("results", []):
                out.append({"participant_id": item.get("participant_id") or item.get("participant"),
                            "status": item.get("status"), "submission_id": item.get("id"),
                            "entered_code": item.get("entered_code")})
            url = ((page.get("_links") or {}).get("next") or {}).get("href")
            params = None  # the next link carries them
        raise ProlificError(f"more than {MAX_PAGES} pages of submissions")

    def set_up_bonuses(self, study_id: str, lines: list[tuple[str, str]]) -> str:
        """Create a bulk bonus payment (not paid yet); its id."""
        body = {"study_id": study_id, "csv_bonuses": "".join(f"{pid},{amount}\n" for pid, amount in lines)}
        return str(self._call("POST", "/api/v1/submissions/bonus-payments/", json=body)["id"])

    def pay_bonuses(self, bulk_id: str) -> None:
        """Pay a bulk bonus payment set up before."""
        self._call("POST", f"/api/v1/bulk-bonus-payments/{bulk_id}/pay/")


def submissions_csv(rows: list[dict[str, Any]]) -> str:
    """Submissions as a CSV like Prolific's export (what PUT .../prolific/submissions takes)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["Submission id", "Participant id", "Status", "Completion code"])
    for r in rows:
        writer.writerow([r.get("submission_id") or "", r["participant_id"], r["status"], r.get("entered_code") or ""])
    return buffer.getvalue()
