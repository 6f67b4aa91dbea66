"""The browser secret: a random value in an HttpOnly, SameSite=Lax cookie set at join; a returning participant
proves with it (or with their external session id) that they are the one who joined."""

from __future__ import annotations

import secrets

from fastapi import Request, Response

COOKIE = "tableteach_browser"
MAX_AGE = 90 * 24 * 3600  # seconds: longer than any study


def browser_secret(request: Request) -> str:
    """The secret of this browser: from its cookie if it is well-formed, else a new one (set it on the answer)."""
    value = request.cookies.get(COOKIE, "")
    if 32 <= len(value) <= 64 and all(c.isalnum() or c in "-_" for c in value):
        return value
    return secrets.token_urlsafe(32)


def remember_browser(request: Request, response: Response, secret: str) -> None:
    """Set (or refresh) the browser's cookie: HttpOnly, SameSite=Lax (sent on the top-level link from Prolific),
    Secure when the request came over HTTPS."""
    secure = request.url.scheme == "https" or request.headers.get("x-forwarded-proto") == "https"
    response.set_cookie(COOKIE, secret, max_age=MAX_AGE, path="/", httponly=True, samesite="lax", secure=secure)
