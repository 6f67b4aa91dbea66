"""Fault injection: kill -9 the study server at random points of real sessions, hold its database locked, kill its
robot worker mid-execution, and check that every participant still finishes with only what their page does by
itself (reading its state until the robot has caught up), and that nothing acknowledged is lost.

    python benchmarks/faults.py --seeds 50                  # SQLite, one process, the MuJoCo robot
    python benchmarks/faults.py --seeds 10 --postgres       # PostgreSQL, two processes (a kill moves the
                                                            # participant to the other one, as the proxy does)

Each seed is one participant's session with one fault at a seeded point: a kill -9 (during placements, right
after a placement was acknowledged, during an execution's work-out, right after an execution was started),
the database held locked for --lock-seconds in the middle of label stores, or the robot worker killed while it
works an execution out. Loopback only; every wait is bounded. Prints a line per seed and the counts.
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
import uuid
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]
TOKEN = "fault-injection-experimenter-token-0123"
OBJECTS = ["dinner_plate", "small_plate", "bowl", "fork", "knife"]
FAULTS = ("kill_placing", "kill_after_place", "kill_working_out", "kill_after_start", "lock_database", "kill_worker")
STUDY = {"name": "faults", "tasks": [{"key": "task1"}], "conditions": ["active"], "n_practice": 0,
         "n_demonstrations": 2, "n_queries": 2, "n_tests": 1, "questionnaire": []}
WAIT_SECONDS = 120.0  # the page waits this long for the robot before the participant gives up


def free_port() -> int:
    """A TCP port that was free a moment ago on 127.0.0.1."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    """`tableteach serve` in a subprocess on a loopback port; kill() is a crash."""

    def __init__(self, folder: Path, database_url: str, name: str) -> None:
        self.folder, self.database_url, self.name = folder, database_url, name
        self.proc: subprocess.Popen[bytes] | None = None
        self.port = free_port()

    @property
    def url(self) -> str:
        """Base URL."""
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> "Server":
        """Start and wait until /healthz answers (RuntimeError if it exits or never answers)."""
        env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": TOKEN, "TABLETEACH_ROBOT": "mujoco",
               "TABLETEACH_DATA_DIR": str(self.folder / "data"), "TABLETEACH_ROBOT_WORKERS": "1",
               # the motion plays 8x faster (the same work, shorter waits); every participant joins from loopback
               "TABLETEACH_ROBOT_SPEED": "8", "TABLETEACH_JOINS_PER_ADDRESS": "100000"}
        log = open(self.folder / f"{self.name}.log", "ab")
        self.proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--port", str(self.port),
                                      "--database-url", self.database_url], env=env, stdout=log,
                                     stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server {self.name} exited with {self.proc.returncode}")
            try:
                if httpx.get(f"{self.url}/healthz", timeout=1).status_code == 200:
                    return self
            except httpx.TransportError:
                time.sleep(0.1)
        raise RuntimeError(f"server {self.name} did not answer /healthz within 60 s")

    def kill(self) -> None:
        """SIGKILL the server and its robot workers: nothing gets a chance to flush."""
        if self.proc is None or self.proc.poll() is not None:
            return
        children = _children(self.proc.pid)
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=30)
        for pid in children:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def kill_worker(self) -> bool:
        """SIGKILL the server's robot worker processes; whether there was one."""
        if self.proc is None:
            return False
        children = _children(self.proc.pid)
        for pid in children:
            os.kill(pid, signal.SIGKILL)
        return bool(children)

    def stop(self) -> None:
        """SIGTERM, then SIGKILL if it lingers."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.kill()


def _children(pid: int) -> list[int]:
    try:
        out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.TimeoutExpired):
        return []
    return [int(x) for x in out.split()]


@dataclass
class Session:
    """One scripted participant that does only what the page lets it do, and remembers what was acknowledged."""

    servers: list[Server]
    rng: random.Random
    token: str = ""
    acked: list[tuple[str, Any]] = field(default_factory=list)
    current: int = 0

    @property
    def server(self) -> Server:
        return self.servers[self.current]

    def request(self, method: str, path: str, body: Any = None, key: str | None = None) -> httpx.Response:
        """One request; a refused connection (the process is gone) or a 503 is tried again, on the other process
        when there are two, with the same idempotency key, until WAIT_SECONDS."""
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        if key:
            headers["Idempotency-Key"] = key
        deadline = time.monotonic() + WAIT_SECONDS
        while True:
            try:
                r = httpx.request(method, f"{self.server.url}{path}", json=body, headers=headers, timeout=30)
                if r.status_code != 503:
                    return r
                wait = float(r.headers.get("Retry-After", "1"))
            except httpx.TransportError:
                wait = 0.2
                if len(self.servers) > 1:
                    self.current = (self.current + 1) % len(self.servers)
            if time.monotonic() > deadline:
                raise TimeoutError(f"{method} {path}: no answer for {WAIT_SECONDS} s")
            time.sleep(min(wait, 2.0))

    def act(self, path: str, body: Any = None) -> dict[str, Any]:
        """A participant action with an idempotency key; remembered once acknowledged."""
        r = self.request("POST", path, body, key=uuid.uuid4().hex)
        if r.status_code != 200:
            raise RuntimeError(f"POST {path} answered {r.status_code}: {r.text[:300]}")
        self.acked.append((path, body))
        return r.json()

    def state(self) -> dict[str, Any]:
        r = self.request("GET", "/api/v1/me")
        r.raise_for_status()
        return r.json()

    def wait_for(self, ready: Any, what: str) -> dict[str, Any]:
        """Read the state (as the page does on its own) until ready(state); TimeoutError naming what never came."""
        deadline = time.monotonic() + WAIT_SECONDS
        while True:
            state = self.state()
            if ready(state):
                return state
            if time.monotonic() > deadline:
                raise TimeoutError(f"stuck: {what} never came (stage {state['stage']}, step {state['step']})")
            time.sleep(0.25)


def _open_study(url: str) -> str:
    headers = {"Authorization": f"Bearer {TOKEN}"}
    r = httpx.post(f"{url}/api/v1/studies", json=STUDY, headers=headers, timeout=30)
    r.raise_for_status()
    study = r.json()["id"]
    httpx.post(f"{url}/api/v1/studies/{study}/open", headers=headers, timeout=30).raise_for_status()
    return study


def _hold_lock(db_path: Path, seconds: float) -> None:
    """Hold SQLite's write lock from another process for `seconds` (as a backup tool or a stuck writer would)."""
    conn = sqlite3.connect(db_path, timeout=30)
    try:
        conn.execute("BEGIN IMMEDIATE")
        time.sleep(seconds)
    finally:
        conn.rollback()
        conn.close()


def run_session(servers: list[Server], study: str, fault: str, rng: random.Random, lock_seconds: float,
                db_path: Path | None, restart: Any) -> dict[str, Any]:
    """One participant's whole session with `fault` at a seeded point; what happened."""
    s = Session(servers, rng)
    r = s.request("POST", f"/api/v1/studies/{study}/join", {})
    r.raise_for_status()
    s.token = r.json()["token"]
    consent = r.json()["state"]["consent"]["version"]
    s.act("/api/v1/me/consent", {"consent_version": consent, "agree": True})
    state = s.act("/api/v1/me/instructions")
    when = rng.randrange(1, 5)  # which placement, or which execution, the fault comes at
    injected = False

    def inject() -> None:
        nonlocal injected
        injected = True
        if fault == "lock_database" and db_path is not None:
            _hold_lock(db_path, lock_seconds)
        elif fault == "kill_worker":
            time.sleep(rng.uniform(0.0, 0.3))
            s.server.kill_worker()
        else:
            time.sleep(rng.uniform(0.0, 0.15))
            restart(s.server)

    placements = 0
    executions = 0
    while state["stage"] == "task":
        step = state["step"]
        if step["kind"] in ("practice", "demonstration"):
            objects = rng.sample(OBJECTS, rng.randrange(2, 5))
            for obj in objects:
                s.wait_for(lambda st: st["demonstration"] is None or st["demonstration"]["settled"],
                           "the robot's report of the previous placement")
                guard = {"task_index": state["task"]["index"], "step_kind": step["kind"], "step_index": step["index"]}
                state = s.act("/api/v1/me/placements", {"object": obj, **guard})
                placements += 1
                if not injected and placements == when and fault in ("kill_placing", "kill_after_place",
                                                                       "lock_database"):
                    if fault == "kill_placing":
                        inject()  # the robot is still placing: its labels are not stored yet
                    elif fault == "lock_database":
                        inject()
                    else:
                        s.wait_for(lambda st: st["demonstration"]["settled"], "the labels")
                        inject()
            state = s.wait_for(lambda st: st["demonstration"]["settled"], "the robot's report of every placement")
            guard = {"task_index": state["task"]["index"], "step_kind": step["kind"], "step_index": step["index"]}
            state = s.act("/api/v1/me/demonstration/finish", guard)
        else:
            guard = {"task_index": state["task"]["index"], "step_kind": step["kind"], "step_index": step["index"]}
            state = s.act("/api/v1/me/execution", guard)
            executions += 1
            if not injected and executions == max(1, when - 1) and fault in ("kill_working_out", "kill_after_start",
                                                                              "kill_worker"):
                if fault == "kill_after_start":
                    time.sleep(rng.uniform(0.5, 2.0))
                inject()
            state = s.wait_for(lambda st: st["execution"] is not None and st["execution"]["status"] == "finished",
                               "the end of the robot's execution")
            body = {"acceptable": rng.random() < 0.5 if step["kind"] == "query" else None, **guard}
            state = s.act("/api/v1/me/assessment", body)
    if not injected:
        inject()  # a fault the session's shape did not reach (few placements): at the end, harmlessly
    lost = _lost(s)
    return {"stage": state["stage"], "injected": injected, "placements": placements, "executions": executions,
            "acked": len(s.acked), "lost": lost}


def _lost(s: Session) -> int:
    """Acknowledged placements, demonstrations and verdicts missing from the participant's own event log."""
    r = httpx.get(f"{s.server.url}/api/v1/studies", headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30)
    r.raise_for_status()
    state = s.state()
    study = state["study_id"]
    events = httpx.get(f"{s.server.url}/api/v1/studies/{study}/exports/events.csv",
                       headers={"Authorization": f"Bearer {TOKEN}"}, timeout=60).text
    import csv
    import io

    mine = [e for e in csv.DictReader(io.StringIO(events)) if int(e["participant_id"]) == state["participant_id"]]
    kinds = Counter(e["kind"] for e in mine)
    want = Counter({"/api/v1/me/placements": "place", "/api/v1/me/demonstration/finish": "demonstration",
                    "/api/v1/me/assessment": "assessment"}.get(path, "") for path, _ in s.acked)
    del want[""]
    return sum(max(0, n - kinds.get(kind, 0)) for kind, n in want.items())


def main(argv: list[str] | None = None) -> int:
    """Run the seeds and print the counts (exit 1 if any participant was stranded or lost an acknowledged action)."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=12, help="sessions to run, one fault each (default 12)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--postgres", action="store_true", help="PostgreSQL with two server processes")
    parser.add_argument("--lock-seconds", type=float, default=10.0, help="how long the database is held locked")
    parser.add_argument("--faults", default=",".join(FAULTS), help=f"comma-separated, from {', '.join(FAULTS)}")
    args = parser.parse_args(argv)
    faults = [f for f in args.faults.split(",") if f]
    unknown = sorted(set(faults) - set(FAULTS))
    if unknown:
        parser.error(f"unknown fault {unknown[0]!r}: expected some of {', '.join(FAULTS)}")
    if args.postgres:
        faults = [f for f in faults if f != "lock_database"]  # the SQLite lock fault has no PostgreSQL form here
    counts: Counter[str] = Counter()
    with ExitStack() as stack, tempfile.TemporaryDirectory(prefix="tableteach-faults-") as tmp:
        folder = Path(tmp)
        if args.postgres:
            from tableteach.db.throwaway_postgres import throwaway_postgres

            url = stack.enter_context(throwaway_postgres())
            db_path = None
        else:
            db_path = folder / "faults.db"
            url = f"sqlite:///{db_path}"
        from tableteach.db.migrate import upgrade_head

        upgrade_head(url)
        servers = [Server(folder, url, f"app{i}").start() for i in range(2 if args.postgres else 1)]
        stack.callback(lambda: [srv.stop() for srv in servers])
        study = _open_study(servers[0].url)

        def restart(server: Server) -> None:
            server.kill()
            counts["kills"] += 1
            if not args.postgres:
                server.start()  # one process: the participant waits for it to come back
            else:
                server.start()  # the other process serves meanwhile; this one comes back later

        for seed in range(args.first_seed, args.first_seed + args.seeds):
            fault = faults[seed % len(faults)]
            rng = random.Random(seed)
            t0 = time.monotonic()
            try:
                result = run_session(servers, study, fault, rng, args.lock_seconds, db_path, restart)
            except Exception as exc:  # noqa: BLE001 - a stranded participant is the finding, not a crash
                counts["stranded"] += 1
                kept = Path(tempfile.mkdtemp(prefix=f"tableteach-faults-seed{seed}-"))
                for log in folder.glob("*.log"):
                    shutil.copy(log, kept / log.name)
                print(f"seed {seed:3d} {fault:17s} STRANDED: {exc} (server logs kept in {kept})", flush=True)
                continue
            counts[fault] += 1
            counts["finished" if result["stage"] in ("done", "questionnaire") else "not_finished"] += 1
            counts["lost_acks"] += result["lost"]
            counts["acked"] += result["acked"]
            print(f"seed {seed:3d} {fault:17s} {result['stage']:13s} placements {result['placements']:2d} "
                  f"executions {result['executions']} acked {result['acked']:2d} lost {result['lost']} "
                  f"({time.monotonic() - t0:.1f} s)", flush=True)
    backend = "postgresql, 2 processes" if args.postgres else "sqlite, 1 process"
    print(f"faults {backend}: sessions {args.seeds} finished {counts['finished']} stranded {counts['stranded']} "
          f"kills {counts['kills']} acked {counts['acked']} lost_acks {counts['lost_acks']} "
          + " ".join(f"{f} {counts[f]}" for f in faults))
    return 0 if counts["stranded"] == 0 and counts["lost_acks"] == 0 and counts["not_finished"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
