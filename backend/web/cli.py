"""Server subcommands of `tableteach`: serve, migrate, backup, restore, teach (a scripted teacher over HTTP), export,
key, hash-token, warm-robot."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..config import Settings
from ..core.teachers import DEFAULT_DEMO_MODE, DEMO_MODES


def _settings(args: argparse.Namespace) -> Settings:
    overrides: dict[str, Any] = {}
    for name in ("host", "port", "database_url", "robot", "data_dir"):
        value = getattr(args, name, None)
        if value is not None:
            overrides[name] = value
    if getattr(args, "dev", False) or getattr(args, "demo", False):
        overrides["dev_mode"] = True
    return Settings(**overrides)


def _store_name(settings: Settings) -> str:
    """Where the recordings are kept, in words."""
    return "database" if settings.recording_store == "database" else "data folder"


def cmd_serve(args: argparse.Namespace) -> None:
    """Check (or with --migrate, migrate) the database, optionally seed the demo study, and serve until interrupted."""
    import uvicorn

    from .. import services
    from ..db.migrate import schema_problem, upgrade_head
    from .app import create_app
    from .auth import experimenter_checker
    from .limits import LimitedHttpToolsProtocol, raise_open_files_limit
    from .dev_token import dev_token_path

    settings = _settings(args)
    open_files, _hard = raise_open_files_limit()  # every held connection and event stream is a file descriptor
    experimenter_checker(settings)  # refuses a missing or weak experimenter secret before touching the database
    if args.migrate or args.demo:
        upgrade_head(settings.database_url)
    else:
        problem = schema_problem(settings.database_url, _safe_url(settings.database_url))
        if problem is not None:
            raise ValueError(problem)  # one line on stderr, exit 2
    app = create_app(settings)
    base = settings.public_url or f"http://{settings.host}:{settings.port}"
    lines = [f"TableTeach serving on http://{settings.host}:{settings.port} "
             f"(database {_safe_url(settings.database_url)}, "
             f"robot {settings.robot}, recordings in the {_store_name(settings)})",
             f"dashboard: {base}/dashboard   API schema: {base}/openapi.json"
             + (f"   API docs (dev mode): {base}/docs" if settings.dev_mode else "")]
    if args.demo:
        study = services.seed_demo_study(app.state.context)
        lines += [f"demo study id: {study['id']}",
                  f"participant link: {base}/study/{study['id']}/join?PROLIFIC_PID=demo-participant"]
    if app.state.dev_token:
        lines.append(f"development experimenter token (dev mode only; kept in {dev_token_path(settings.data_dir)}): "
                     f"{app.state.dev_token}")
    if open_files < 2 * settings.max_event_streams:
        lines.append(f"warning: this process may open only {open_files} files (ulimit -n) for up to "
                     f"{settings.max_event_streams} event streams plus other connections; raise the limit")
    print("\n".join(lines), flush=True)
    protocol = LimitedHttpToolsProtocol.with_timeouts(settings.header_timeout_seconds, settings.body_timeout_seconds)
    uvicorn.run(app, host=settings.host, port=settings.port, log_level=args.log_level, access_log=False,
                timeout_graceful_shutdown=5, http=protocol, timeout_keep_alive=settings.keep_alive_seconds,
                # The one websocket is the 3D view's: viser's messages are zstd-compressed already (their meshes
                # raw), and per-message deflate held about 50 KiB of zlib state per open view.
                ws_per_message_deflate=False,
                # Behind the proxy the client's address (for the wrong-key limit) comes from X-Forwarded-For.
                proxy_headers=True, forwarded_allow_ips=settings.forwarded_allow_ips)


def cmd_migrate(args: argparse.Namespace) -> dict:
    """Bring the database to the newest schema revision; which revision it was at and is at now."""
    from ..db.migrate import current_revision, upgrade_head

    settings = _settings(args)
    before = current_revision(settings.database_url)
    upgrade_head(settings.database_url)
    return {"database": _safe_url(settings.database_url), "from_revision": before,
            "to_revision": current_revision(settings.database_url)}


def cmd_backup(args: argparse.Namespace) -> dict:
    """Back up the database and the data folder (recordings) into one archive, also while the server runs."""
    from ..db.backup import create_backup

    settings = _settings(args)
    manifest = create_backup(settings.database_url, settings.data_dir, args.out)
    return {"out": str(args.out), "database": _safe_url(settings.database_url), "data_dir": str(settings.data_dir),
            "schema_revision": manifest["schema_revision"], "files": len(manifest["files"]),
            "bytes": sum(f["size"] for f in manifest["files"])}


def cmd_restore(args: argparse.Namespace) -> dict:
    """Restore a backup into an empty database and data folder (stop the server first)."""
    from ..db.backup import restore_backup
    from ..db.migrate import head_revision

    settings = _settings(args)
    manifest = restore_backup(args.archive, settings.database_url, settings.data_dir, force=args.force)
    behind = manifest["schema_revision"] != head_revision()
    return {"restored": str(args.archive), "database": _safe_url(settings.database_url),
            "data_dir": str(settings.data_dir), "schema_revision": manifest["schema_revision"],
            "created_at": manifest["created_at"], "files": len(manifest["files"]),
            "next": "tableteach migrate, then tableteach serve" if behind else "tableteach serve"}


def _safe_url(url: str) -> str:
    """The database URL without its password."""
    from urllib.parse import urlsplit, urlunsplit

    parts = urlsplit(url)
    if parts.password:
        netloc = parts.netloc.replace(f":{parts.password}@", ":***@")
        return urlunsplit(parts._replace(netloc=netloc))
    return url


def _quiz_answers(text: str | None) -> dict[str, int]:
    """--quiz-answers "who=1,order=0" as {item id: option number}."""
    out: dict[str, int] = {}
    for part in (text or "").split(","):
        if not part.strip():
            continue
        item, sep, number = part.partition("=")
        if not sep or not item.strip() or not number.strip().isdigit():
            raise ValueError(f"--quiz-answers: {part.strip()!r} is not ITEM=NUMBER (the option's number from 0), "
                             "e.g. who=1,order=0")
        out[item.strip()] = int(number)
    return out


def cmd_teach(args: argparse.Namespace) -> dict:
    """A scripted teacher completes one participant session over HTTP."""
    import httpx

    from ..client import ApiError, ExperimenterClient, StudyKnowledge, run_teacher
    from ..core.domain import DINNER_TASK_FORMULAS
    from ..core.ltl import parse

    if not 0.0 <= args.noise <= 1.0:
        raise ValueError(f"--noise must be a probability in [0, 1], got {args.noise}")
    if not 0.0 <= args.attention_fail_rate <= 1.0:
        raise ValueError(f"--attention-fail-rate must be a probability in [0, 1], got {args.attention_fail_rate}")
    if args.session_timeout is not None and args.session_timeout <= 0:
        raise ValueError(f"--session-timeout must be a positive number of seconds, got {args.session_timeout}")
    for truth in args.ground_truth:  # the syntax before any request (the objects are checked against the study's)
        if truth not in DINNER_TASK_FORMULAS:
            parse(truth)
    try:
        knows = StudyKnowledge(attention_fail_rate=args.attention_fail_rate)
        if args.token:
            with ExperimenterClient(args.server, token=args.token) as experimenter:
                knows = StudyKnowledge.of_study(experimenter.study_spec(args.study),
                                                attention_fail_rate=args.attention_fail_rate)
        knows.quiz_answers.update(_quiz_answers(args.quiz_answers))
        run = run_teacher(args.server, args.study, args.ground_truth, noise=args.noise, seed=args.seed,
                          demo_mode=args.demo_mode,
                          prolific_pid=args.prolific_pid, session_id=args.session_id, knows=knows,
                          timeout=args.session_timeout)
    except ApiError as exc:
        raise ValueError(f"the server refused a request: {exc}") from exc
    except httpx.HTTPError as exc:
        raise ValueError(f"cannot reach {args.server}: {exc}") from exc
    except TimeoutError as exc:
        raise ValueError(f"{exc}; give a longer --session-timeout") from exc
    return {"study_id": args.study, **run.summary()}


def cmd_export(args: argparse.Namespace) -> dict:
    """Download a study's CSV exports into a folder."""
    import httpx

    from ..client import ApiError, ExperimenterClient

    client = ExperimenterClient(args.server, token=args.token)
    try:
        rows = client.export_all(args.study, args.out, include_pilot=args.include_pilot)
    except ApiError as exc:
        raise ValueError(f"the server refused the export: {exc}") from exc
    except httpx.HTTPError as exc:
        raise ValueError(f"cannot reach {args.server}: {exc}") from exc
    finally:
        client.close()
    return {"study_id": args.study, "out": str(args.out), "rows": rows}


def cmd_key(args: argparse.Namespace) -> dict:
    """A new generated experimenter key (for TABLETEACH_EXPERIMENTER_TOKEN) and its hash (for _HASH)."""
    from .auth import generate_key, hash_secret

    key = generate_key()
    return {"experimenter_token": key, "experimenter_token_hash": hash_secret(key)}


def cmd_hash_token(args: argparse.Namespace) -> dict:
    """Hash an experimenter key for TABLETEACH_EXPERIMENTER_TOKEN_HASH (reads it from stdin)."""
    from .auth import hash_secret, key_problem

    secret = sys.stdin.readline().rstrip("\n")
    if not secret:
        raise ValueError("no key on stdin; pipe it in, e.g. `printf %s \"$TOKEN\" | tableteach hash-token`")
    problem = key_problem(secret)
    if problem is not None:
        raise ValueError(f"this key is too weak: {problem}")
    return {"experimenter_token_hash": hash_secret(secret)}


def cmd_warm_robot(args: argparse.Namespace) -> dict:
    """Simulate the MuJoCo robot's placements ahead, into the data folder's clip files."""
    import time

    from .robots import warm_robot

    if args.tasks < 1:
        raise ValueError(f"--tasks {args.tasks}: expected at least 1 (how many tasks the studies have)")
    settings = _settings(args)
    started = time.process_time()
    done = warm_robot(settings, args.tasks)
    return {"data_dir": str(settings.data_dir), "tasks": args.tasks, **done,
            "cpu_seconds": round(time.process_time() - started, 1)}


def register(sub: argparse._SubParsersAction) -> None:
    """Add the server subcommands to the `tableteach` parser."""
    serve = sub.add_parser("serve", help="migrate the database and run the study server")
    serve.add_argument("--host", help="interface to listen on (default 127.0.0.1; TABLETEACH_HOST)")
    serve.add_argument("--port", type=int, help="port (default 8000; TABLETEACH_PORT)")
    serve.add_argument("--database-url", help="SQLAlchemy URL (default sqlite:///var/tableteach.db)")
    serve.add_argument("--demo", action="store_true",
                       help="seed the demo study (implies --dev)")
    serve.add_argument("--robot", choices=["trace", "mujoco"],
                       help="robot: mujoco (default: the simulated arm shown in the page) or trace "
                            "(no physics, for tests and load runs); TABLETEACH_ROBOT")
    serve.add_argument("--data-dir", help="folder for robot recordings (default var/data; TABLETEACH_DATA_DIR)")
    serve.add_argument("--dev", action="store_true", help="dev mode: a generated experimenter token if none is set")
    serve.add_argument("--migrate", action="store_true",
                       help="migrate the database to the newest schema first (without it, serve refuses a database "
                            "that is not migrated; --demo implies it)")
    serve.add_argument("--log-level", default="warning", choices=["critical", "error", "warning", "info", "debug"])
    serve.set_defaults(run=cmd_serve)

    migrate = sub.add_parser("migrate", help="migrate the database to the newest schema (back it up first)")
    migrate.add_argument("--database-url", help="SQLAlchemy URL (default: TABLETEACH_DATABASE_URL)")
    migrate.set_defaults(run=cmd_migrate)

    backup = sub.add_parser("backup", help="back up the database and the recordings into one .tar.gz "
                                           "(safe while the server runs)")
    backup.add_argument("--out", required=True, help="archive to write, e.g. backups/tableteach-2026-12-01.tar.gz")
    backup.add_argument("--database-url", help="SQLAlchemy URL (default: TABLETEACH_DATABASE_URL)")
    backup.add_argument("--data-dir", help="folder of the recordings (default: TABLETEACH_DATA_DIR)")
    backup.set_defaults(run=cmd_backup)

    restore = sub.add_parser("restore", help="restore a backup into an empty database and data folder")
    restore.add_argument("archive", help="a file made by `tableteach backup`")
    restore.add_argument("--database-url", help="SQLAlchemy URL to restore into (default: TABLETEACH_DATABASE_URL)")
    restore.add_argument("--data-dir", help="folder to restore the recordings into (default: TABLETEACH_DATA_DIR)")
    restore.add_argument("--force", action="store_true",
                         help="replace a database that has tables and files that exist (default: refuse)")
    restore.set_defaults(run=cmd_restore)

    teach = sub.add_parser("teach", help="a scripted teacher completes a participant session over HTTP")
    teach.add_argument("--server", required=True, help="server base URL, e.g. http://127.0.0.1:8000")
    teach.add_argument("--study", required=True, help="study id")
    teach.add_argument("--ground-truth", required=True, action="append",
                       help="the teacher's formula over the study's objects (the dinner table's, or its own), or "
                       "task1 / task2 on the dinner table; repeat once per task of the study")
    teach.add_argument("--noise", type=float, default=0.0, help="probability of a flipped verdict (default 0)")
    teach.add_argument("--demo-mode", choices=list(DEMO_MODES), default=DEFAULT_DEMO_MODE,
                       help=f"how the teacher demonstrates (default {DEFAULT_DEMO_MODE}, the authors' demonstrator)")
    teach.add_argument("--seed", type=int, default=0, help="the teacher's random seed")
    teach.add_argument("--prolific-pid", help="external participant id")
    teach.add_argument("--session-id", help="external session id (a rerun with the same --prolific-pid and "
                                            "--session-id resumes the same session)")
    teach.add_argument("--token", help="experimenter token: the teacher reads the study definition and answers the "
                       "quiz and the attention checks correctly (and refuses before joining a study it cannot "
                       "finish)")
    teach.add_argument("--quiz-answers", help="the quiz's answers without the token, e.g. who=1,order=0 (option "
                       "numbers from 0)")
    teach.add_argument("--attention-fail-rate", type=float, default=0.0,
                       help="probability of answering an attention check wrongly (default 0; needs --token)")
    teach.add_argument("--session-timeout", type=float, default=None,
                       help="seconds for the whole session (default: three times the server's estimate, at least "
                       "600, which fits the demo study with the MuJoCo robot at real speed)")
    teach.set_defaults(run=cmd_teach)

    export = sub.add_parser("export", help="download a study's CSV exports")
    export.add_argument("--server", required=True, help="server base URL")
    export.add_argument("--study", required=True, help="study id")
    export.add_argument("--token", required=True, help="experimenter token")
    export.add_argument("--out", required=True,
                        help="folder to write the files of exports.zip: participants/events/steps/beliefs/"
                        "questionnaire.csv, codebook.csv, datapackage.json and study.json")
    export.add_argument("--include-pilot", action="store_true", help="also pilot participants (left out by default)")
    export.set_defaults(run=cmd_export)

    warm = sub.add_parser("warm-robot", help="simulate every placement the MuJoCo robot's tables can ask for, once "
                                             "per data folder (about 80 s of CPU per task; optional: it only "
                                             "spares the first participants' physics)")
    warm.add_argument("--tasks", type=int, default=2, help="how many tasks (task indices 0..N-1; default 2)")
    warm.add_argument("--data-dir", help="the server's data folder (default var/data; TABLETEACH_DATA_DIR)")
    warm.set_defaults(run=cmd_warm_robot)

    key = sub.add_parser("key", help="generate an experimenter key (TABLETEACH_EXPERIMENTER_TOKEN) and its hash")
    key.set_defaults(run=cmd_key)

    hash_token = sub.add_parser("hash-token", help="hash an experimenter key read from stdin")
    hash_token.set_defaults(run=cmd_hash_token)
