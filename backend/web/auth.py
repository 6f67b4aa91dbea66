"""Experimenter credentials: PBKDF2 hashes, constant-time checks, and the refusal of weak secrets outside dev mode."""

from __future__ import annotations

import base64
import hashlib
import hmac
import secrets
import threading

from ..config import Settings
from .dev_token import persistent_dev_token

ITERATIONS = 200_000
WEAK_SECRETS = {"", "changeme", "change-me", "password", "secret", "admin", "dev", "tableteach", "token", "test"}
MIN_LENGTH = 12


def hash_secret(secret: str, *, iterations: int = ITERATIONS) -> str:
    """A salted PBKDF2-SHA256 hash: pbkdf2_sha256$iterations$salt$digest."""
    salt = secrets.token_bytes(16)
    digest = hashlib.pbkdf2_hmac("sha256", secret.encode(), salt, iterations)
    b64 = lambda b: base64.urlsafe_b64encode(b).decode().rstrip("=")  # noqa: E731
    return f"pbkdf2_sha256${iterations}${b64(salt)}${b64(digest)}"


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


class SecretChecker:
    """Checks a presented secret against a stored hash; remembers verified secrets (as SHA-256) to stay fast."""

    def __init__(self, stored_hash: str) -> None:
        try:
            scheme, iterations, salt, digest = stored_hash.split("$")
            if scheme != "pbkdf2_sha256":
                raise ValueError(scheme)
            self._iterations, self._salt, self._digest = int(iterations), _unb64(salt), _unb64(digest)
        except ValueError as exc:
            raise ValueError("experimenter_token_hash must look like pbkdf2_sha256$<iterations>$<salt>$<digest> "
                             "(make one with `tableteach hash-token`)") from exc
        self._verified: set[bytes] = set()
        self._lock = threading.Lock()

    def check(self, secret: str) -> bool:
        """Whether the secret matches the stored hash."""
        quick = hashlib.sha256(secret.encode()).digest()
        with self._lock:
            if quick in self._verified:
                return True
        ok = hmac.compare_digest(
            hashlib.pbkdf2_hmac("sha256", secret.encode(), self._salt, self._iterations), self._digest
        )
        if ok:
            with self._lock:
                self._verified.add(quick)
        return ok


def experimenter_checker(settings: Settings) -> tuple[SecretChecker, str | None]:
    """The checker for the configured secret and, in dev mode without one, a development token kept under the
    data folder.

    Outside dev mode a missing, short or well-known secret is refused (ValueError naming the setting)."""
    token = settings.experimenter_token.get_secret_value() if settings.experimenter_token else None
    if settings.experimenter_token_hash:
        return SecretChecker(settings.experimenter_token_hash), None
    if token is not None and (settings.dev_mode or (len(token) >= MIN_LENGTH and token.lower() not in WEAK_SECRETS)):
        return SecretChecker(hash_secret(token, iterations=1_000 if settings.dev_mode else ITERATIONS)), None
    if settings.dev_mode:
        generated = persistent_dev_token(settings.data_dir)  # the same token after a restart
        return SecretChecker(hash_secret(generated, iterations=1_000)), generated
    if token is None:
        raise ValueError("no experimenter secret: set TABLETEACH_EXPERIMENTER_TOKEN (or _HASH), "
                         "or run in dev mode (TABLETEACH_DEV_MODE=1 / --dev) for a generated one")
    raise ValueError(f"TABLETEACH_EXPERIMENTER_TOKEN is too weak: expected at least {MIN_LENGTH} characters and not a "
                     "well-known default (outside dev mode)")
