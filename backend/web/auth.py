"""Experimenter credentials: a SHA-256 digest compared in constant time, generated keys, and a limit on wrong keys.

The experimenter key is a generated high-entropy token (`tableteach key`), so a fast digest is enough: a wrong
key costs microseconds, not the ~0.1 s of CPU a password hash would (which let wrong keys starve the server).
PBKDF2 hashes from earlier versions (pbkdf2_sha256$...) are still accepted; their checks run in the thread pool.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import math
import secrets
import threading

from ..config import Settings
from .dev_token import persistent_dev_token

MIN_KEY_LENGTH = 32
MIN_KEY_BITS = 128  # estimated as length x log2(distinct characters)


def generate_key() -> str:
    """A new experimenter key: 32 random bytes, URL-safe (43 characters)."""
    return secrets.token_urlsafe(32)


def hash_secret(secret: str) -> str:
    """The stored form of a key: sha256$<hex digest> (the key itself is random, so no salt or stretching)."""
    return "sha256$" + hashlib.sha256(secret.encode()).hexdigest()


def key_problem(key: str) -> str | None:
    """Why a key does not look generated (too short or too repetitive), or None if it is acceptable."""
    distinct = len(set(key))
    bits = len(key) * math.log2(distinct) if distinct > 1 else 0.0
    if len(key) < MIN_KEY_LENGTH or bits < MIN_KEY_BITS:
        return (f"expected a generated key of at least {MIN_KEY_LENGTH} varied characters (about {MIN_KEY_BITS} bits), "
                f"got {len(key)} characters with {distinct} distinct; make one with `tableteach key`")
    return None


def _unb64(text: str) -> bytes:
    return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))


class SecretChecker:
    """Checks a presented key against its stored form: sha256$<hex> (fast) or a legacy pbkdf2_sha256 hash."""

    def __init__(self, stored_hash: str) -> None:
        scheme, _, rest = stored_hash.partition("$")
        self._pbkdf2: tuple[int, bytes, bytes] | None = None
        try:
            if scheme == "sha256":
                self._digest = bytes.fromhex(rest)
                if len(self._digest) != 32:
                    raise ValueError(rest)
            elif scheme == "pbkdf2_sha256":
                iterations, salt, digest = rest.split("$")
                self._pbkdf2 = (int(iterations), _unb64(salt), _unb64(digest))
                self._digest = b""
            else:
                raise ValueError(scheme)
        except ValueError as exc:
            raise ValueError("experimenter_token_hash must look like sha256$<64 hex digits> (make one with "
                             "`tableteach hash-token`) or pbkdf2_sha256$<iterations>$<salt>$<digest>") from exc
        self._verified: set[bytes] = set()  # legacy hashes: SHA-256 of keys already verified
        self._lock = threading.Lock()

    @property
    def slow(self) -> bool:
        """Whether a check may cost real CPU (a legacy PBKDF2 hash: run it off the event loop)."""
        return self._pbkdf2 is not None

    def quick_check(self, secret: str) -> bool | None:
        """Whether the secret is the key when that costs one SHA-256 (None: only the slow legacy check can tell)."""
        quick = hashlib.sha256(secret.encode()).digest()
        if self._pbkdf2 is None:
            return hmac.compare_digest(quick, self._digest)
        with self._lock:
            return True if quick in self._verified else None

    def check(self, secret: str) -> bool:
        """Whether the secret is the key (constant-time comparison of digests)."""
        known = self.quick_check(secret)
        if known is not None:
            return known
        quick = hashlib.sha256(secret.encode()).digest()
        assert self._pbkdf2 is not None  # quick_check answers for every other kind of secret
        iterations, salt, digest = self._pbkdf2
        ok = hmac.compare_digest(hashlib.pbkdf2_hmac("sha256", secret.encode(), salt, iterations), digest)
        if ok:
            with self._lock:
                self._verified.add(quick)
        return ok


def experimenter_checker(settings: Settings) -> tuple[SecretChecker, str | None]:
    """The checker for the configured key and, in dev mode without one, a generated development key.

    Outside dev mode a missing key, or one that does not look generated, is refused (ValueError naming the setting)."""
    token = settings.experimenter_token.get_secret_value() if settings.experimenter_token else None
    if settings.experimenter_token_hash:
        return SecretChecker(settings.experimenter_token_hash), None
    if token is not None and (settings.dev_mode or key_problem(token) is None):
        return SecretChecker(hash_secret(token)), None
    if settings.dev_mode:
        generated = persistent_dev_token(settings.data_dir)  # the same token after a restart
        return SecretChecker(hash_secret(generated)), generated
    if token is None:
        raise ValueError("no experimenter key: set TABLETEACH_EXPERIMENTER_TOKEN (make one with `tableteach key`) "
                         "or _HASH, or run in dev mode (TABLETEACH_DEV_MODE=1 / --dev) for a generated one")
    raise ValueError(f"TABLETEACH_EXPERIMENTER_TOKEN is too weak outside dev mode: {key_problem(token)}")
