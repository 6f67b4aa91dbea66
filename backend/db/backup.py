"""Backups of a running server and their restore: one .tar.gz holding a JSON manifest (format, versions, schema
revision, every file's size and SHA-256), the database (SQLite's online backup, or pg_dump's custom format) and
the data folder's files (the robot recordings). Nothing in it is pickled; restore checks every checksum first."""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import sqlite3
import subprocess
import tarfile
import tempfile
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath
from typing import Any

from sqlalchemy.engine import URL, make_url

FORMAT = "tableteach-backup"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
SQLITE_MEMBER = "database/tableteach.sqlite3"
POSTGRES_MEMBER = "database/tableteach.pgdump"
DATA_PREFIX = "data/"
# Left out of a backup: dev mode's generated key (a secret that is made again) and temporary files.
SKIPPED_DATA_FILES = {"dev-experimenter-token"}
SKIPPED_SUFFIXES = (".tmp", ".part")
# Copies the robot makes again on demand: its caches, and the shared motion each participant's own recording
# files are links to (the archive holds those files themselves, so a restore gives each their own copy).
SKIPPED_DATA_FOLDERS = ("robot-cache/", "recordings/motion/")
STABLE_READ_TRIES = 5


@dataclass(frozen=True)
class BackupFile:
    """One file of a backup: its name in the archive, size and SHA-256."""

    name: str
    size: int
    sha256: str

    def as_json(self) -> dict[str, Any]:
        """The manifest's entry."""
        return {"name": self.name, "size": self.size, "sha256": self.sha256}


def _sqlite_path(url: URL) -> Path:
    if not url.database or url.database == ":memory:":
        raise ValueError(f"cannot back up or restore an in-memory SQLite database ({url}); expected sqlite:///FILE")
    return Path(url.database)


def _libpq(url: URL) -> tuple[str, dict[str, str]]:
    """A libpq connection URI for pg_dump/pg_restore (no password in it) and the environment carrying the password."""
    plain = url.set(drivername="postgresql", password=None)
    env = {**os.environ}
    if url.password is not None:
        env["PGPASSWORD"] = str(url.password)
    return plain.render_as_string(hide_password=False), env


def _postgres_tool(name: str) -> str:
    """pg_dump or pg_restore: on PATH, else the newest of Debian's server packages."""
    found = shutil.which(name)
    if found:
        return found
    candidates = sorted(Path("/usr/lib/postgresql").glob(f"*/bin/{name}"))
    if candidates:
        return str(candidates[-1])
    raise ValueError(f"{name} is not installed: expected PostgreSQL's client programs on PATH "
                     "(Debian: apt-get install postgresql-client)")


def _run(args: list[str], env: dict[str, str] | None, what: str) -> None:
    done = subprocess.run(args, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        detail = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise ValueError(f"{what} failed: {detail}")


def _sha256(path: Path) -> tuple[int, str]:
    digest, size = hashlib.sha256(), 0
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
            size += len(block)
    return size, digest.hexdigest()


def _snapshot_sqlite(source: Path, target: Path) -> None:
    """A consistent copy of a live SQLite database through its online backup API (writers may go on)."""
    if not source.exists():
        raise ValueError(f"no database file at {source}: nothing to back up")
    src = sqlite3.connect(source, timeout=30)
    dst = sqlite3.connect(target)
    try:
        src.backup(dst)
        dst.execute("PRAGMA journal_mode=DELETE")  # one self-contained file in the archive
    finally:
        dst.close()
        src.close()


def _data_files(data_dir: Path) -> list[Path]:
    """The data folder's files to keep, sorted (recordings and .viser motion files)."""
    if not data_dir.exists():
        return []
    out = []
    for path in sorted(data_dir.rglob("*")):
        if not path.is_file() or path.is_symlink():
            continue
        rel = path.relative_to(data_dir)
        if (rel.as_posix() in SKIPPED_DATA_FILES or path.name.endswith(SKIPPED_SUFFIXES)
                or rel.as_posix().startswith(SKIPPED_DATA_FOLDERS)):
            continue
        out.append(path)
    return out


def _stable_bytes(path: Path) -> bytes | None:
    """The file's bytes, read again if it changed while being read (a recording being written); None if it is
    gone (erased meanwhile)."""
    for _ in range(STABLE_READ_TRIES):
        try:
            before = path.stat()
            data = path.read_bytes()
            after = path.stat()
        except FileNotFoundError:
            return None
        if before.st_size == after.st_size == len(data) and before.st_mtime_ns == after.st_mtime_ns:
            return data
    raise ValueError(f"{path} kept changing while it was backed up; try again")


def _add_bytes(tar: tarfile.TarFile, name: str, data: bytes) -> BackupFile:
    info = tarfile.TarInfo(name)
    info.size, info.mode, info.mtime = len(data), 0o600, int(datetime.now(timezone.utc).timestamp())
    tar.addfile(info, io.BytesIO(data))
    return BackupFile(name, len(data), hashlib.sha256(data).hexdigest())


def create_backup(database_url: str, data_dir: Path | str, out: Path | str) -> dict[str, Any]:
    """Write a backup of the database and the data folder to `out` (replaced only once complete); its manifest.

    The database is copied first, then the files, so every recording the copied database names is in it."""
    from ..version import app_version
    from .migrate import current_revision

    url, data_dir, out = make_url(database_url), Path(data_dir), Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    revision = current_revision(database_url)
    if revision is None:
        raise ValueError(f"the database {url.render_as_string(hide_password=True)} has no schema: nothing to back up")
    with tempfile.TemporaryDirectory(prefix=".tableteach-backup-", dir=out.parent) as scratch:
        dump = Path(scratch) / "database"
        if url.get_backend_name() == "sqlite":
            _snapshot_sqlite(_sqlite_path(url), dump)
            kind, member = "sqlite", SQLITE_MEMBER
        elif url.get_backend_name() == "postgresql":
            uri, env = _libpq(url)
            _run([_postgres_tool("pg_dump"), "--format=custom", "--no-owner", "--no-privileges", f"--file={dump}",
                  f"--dbname={uri}"], env, "pg_dump")
            kind, member = "postgresql", POSTGRES_MEMBER
        else:
            raise ValueError(f"cannot back up a {url.get_backend_name()} database; expected sqlite or postgresql")
        partial = Path(scratch) / "backup.tar.gz"
        files: list[BackupFile] = []
        with tarfile.open(partial, "w:gz") as tar:
            size, digest = _sha256(dump)
            tar.add(dump, arcname=member)
            files.append(BackupFile(member, size, digest))
            for path in _data_files(data_dir):
                data = _stable_bytes(path)
                if data is not None:
                    files.append(_add_bytes(tar, DATA_PREFIX + path.relative_to(data_dir).as_posix(), data))
            manifest = {
                "format": FORMAT, "format_version": FORMAT_VERSION,
                "created_at": datetime.now(timezone.utc).isoformat(), "app_version": app_version(),
                "schema_revision": revision, "database": {"kind": kind, "file": member},
                "files": [f.as_json() for f in files],
            }
            _add_bytes(tar, MANIFEST, json.dumps(manifest, indent=1).encode())
        os.replace(partial, out)
    return manifest


def _check_name(name: str) -> str:
    path = PurePosixPath(name)
    if path.is_absolute() or ".." in path.parts or not path.parts or name != path.as_posix():
        raise ValueError(f"the backup names a file outside its folders: {name!r}")
    return name


def _digest_of(tar: tarfile.TarFile, info: tarfile.TarInfo) -> str:
    handle = tar.extractfile(info)
    if handle is None:
        raise ValueError(f"{info.name} is not a regular file")
    digest = hashlib.sha256()
    for block in iter(lambda: handle.read(1 << 20), b""):
        digest.update(block)
    return digest.hexdigest()


def read_manifest(archive: Path | str) -> dict[str, Any]:
    """The backup's manifest, after checking that it is one and that every file in it is whole (ValueError if not)."""
    archive = Path(archive)
    if not archive.is_file():
        raise ValueError(f"{archive}: no such backup file")
    try:
        with tarfile.open(archive, "r:gz") as tar:
            member = tar.getmember(MANIFEST)
            handle = tar.extractfile(member)
            if handle is None:
                raise ValueError(f"{archive}: its {MANIFEST} is not a file")
            manifest = json.loads(handle.read())
            if manifest.get("format") != FORMAT or manifest.get("format_version") != FORMAT_VERSION:
                raise ValueError(f"{archive}: not a {FORMAT} version {FORMAT_VERSION} archive "
                                 f"(its manifest says {manifest.get('format')!r} {manifest.get('format_version')!r})")
            expected = {_check_name(f["name"]): f for f in manifest["files"]}
            seen: set[str] = set()
            for info in tar:
                if info.name == MANIFEST:
                    continue
                if info.name not in expected or not info.isfile():
                    raise ValueError(f"{archive}: holds {info.name!r}, which its manifest does not list as a file")
                digest = _digest_of(tar, info)
                if digest != expected[info.name]["sha256"] or info.size != expected[info.name]["size"]:
                    raise ValueError(f"{archive}: {info.name} is damaged (its checksum differs from the manifest's)")
                seen.add(info.name)
            missing = sorted(set(expected) - seen)
            if missing:
                raise ValueError(f"{archive}: files listed in its manifest are missing: {', '.join(missing[:5])}")
    except (tarfile.TarError, OSError, EOFError, KeyError, json.JSONDecodeError) as exc:
        raise ValueError(f"{archive}: not a readable TableTeach backup ({exc})") from exc
    return manifest


def _database_has_tables(database_url: str) -> bool:
    from sqlalchemy import create_engine, inspect, pool

    url = make_url(database_url)
    if url.get_backend_name() == "sqlite" and not _sqlite_path(url).exists():
        return False
    engine = create_engine(url, poolclass=pool.NullPool)
    try:
        with engine.connect() as connection:
            return bool(inspect(connection).get_table_names())
    finally:
        engine.dispose()


def restore_backup(archive: Path | str, database_url: str, data_dir: Path | str, *,
                   force: bool = False) -> dict[str, Any]:
    """Restore a backup into an empty database and data folder (with force: over what is there); its manifest.

    Every checksum is verified before anything is written. Stop the servers of this database first."""
    from .migrate import known_revisions

    archive, data_dir, url = Path(archive), Path(data_dir), make_url(database_url)
    manifest = read_manifest(archive)
    if manifest["schema_revision"] not in known_revisions():
        raise ValueError(f"the backup's schema revision {manifest['schema_revision']} is newer than this version "
                         "knows: restore it with the version that made it (manifest app_version "
                         f"{manifest['app_version']})")
    kind = manifest["database"]["kind"]
    if kind != url.get_backend_name():
        raise ValueError(f"the backup holds a {kind} database; restore it into a {kind} URL, not "
                         f"{url.get_backend_name()}")
    if not force and _database_has_tables(database_url):
        raise ValueError(f"the database {url.render_as_string(hide_password=True)} already has tables: restore into "
                         "an empty one, or pass --force to replace its contents")
    data_names = [f["name"] for f in manifest["files"] if f["name"].startswith(DATA_PREFIX)]
    if not force:
        clashes = [n for n in data_names if (data_dir / n[len(DATA_PREFIX):]).exists()]
        if clashes:
            raise ValueError(f"{data_dir} already holds files the backup has ({clashes[0]} and {len(clashes) - 1} "
                             "more): restore into an empty data folder, or pass --force to overwrite them")
    data_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".tableteach-restore-", dir=data_dir) as scratch, \
            tarfile.open(archive, "r:gz") as tar:
        for info in tar:
            if info.name == MANIFEST:
                continue
            source = tar.extractfile(info)
            assert source is not None
            if info.name.startswith(DATA_PREFIX):
                target = data_dir / info.name[len(DATA_PREFIX):]
                target.parent.mkdir(parents=True, exist_ok=True)
                staged = target.with_name(target.name + ".part")
                with open(staged, "wb") as f:
                    shutil.copyfileobj(source, f)
                os.replace(staged, target)
            else:
                staged = Path(scratch) / "database"
                with open(staged, "wb") as f:
                    shutil.copyfileobj(source, f)
                _restore_database(staged, kind, url, force=force)
    return manifest


def _restore_database(dump: Path, kind: str, url: URL, *, force: bool) -> None:
    if kind == "sqlite":
        target = _sqlite_path(url)
        target.parent.mkdir(parents=True, exist_ok=True)
        staged = target.with_name(target.name + ".restoring")
        shutil.copyfile(dump, staged)
        for leftover in (target.with_name(target.name + "-wal"), target.with_name(target.name + "-shm")):
            leftover.unlink(missing_ok=True)  # a stale WAL would be replayed into the restored file
        os.replace(staged, target)
        return
    uri, env = _libpq(url)
    args = [_postgres_tool("pg_restore"), "--no-owner", "--no-privileges", "--exit-on-error", "--single-transaction",
            f"--dbname={uri}"]
    if force:
        args[1:1] = ["--clean", "--if-exists"]
    _run([*args, str(dump)], env, "pg_restore")
