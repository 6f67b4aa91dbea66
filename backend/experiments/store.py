"""The output folder of a sweep: config.json, and runs.csv written so that no finished run is lost.

Each finished run's rows are appended in one write and flushed. On resume, a run counts as done
only if all of its rows are present and well formed (a half-written last line is dropped), and
the file is rewritten with the complete runs alone before new rows are appended. When the sweep
ends the rows are sorted, so the file does not depend on which worker finished first.
"""

from __future__ import annotations

import csv
import io
import json
import os
import platform
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any, Iterable

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None  # type: ignore[assignment]

from ..core.session import PROTOCOLS
from .settings import SIZE_DEFAULTS, ExperimentSettings
from .simulate import COLUMNS

CONFIG = "config.json"
RUNS = "runs.csv"
FLOAT_COLUMNS = {"entropy": ".6g", "similarity": ".6g", "map_similarity": ".6g", "seconds": ".3g"}
_COL = {name: i for i, name in enumerate(COLUMNS)}


def versions() -> dict[str, str]:
    """Versions of what produced the numbers."""
    import numpy

    out = {"python": platform.python_version(), "numpy": numpy.__version__}
    for package in ("tableteach", "matplotlib", "dask", "distributed"):
        try:
            out[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            out[package] = "not installed"
    return out


def format_row(row: list[Any]) -> list[str]:
    """A row's CSV fields (floats rounded to what the analysis needs, which also keeps the file small)."""
    out = [str(v) for v in row]
    for name, spec in FLOAT_COLUMNS.items():
        out[_COL[name]] = format(float(row[_COL[name]]) + 0.0, spec)
    return out


def expected_keys(settings: ExperimentSettings) -> set[tuple[str, int, int]]:
    """The (protocol, n_query, n_executions) rows every complete run has."""
    return {
        (protocol, n, k)
        for protocol in PROTOCOLS
        for n in settings.n_query
        for k in range(settings.n_demonstrations + n + 1)
    }


@dataclass
class OutputFolder:
    """A sweep's output folder for one set of settings."""

    path: Path
    settings: ExperimentSettings
    invocations: list[dict[str, Any]] = field(default_factory=list, init=False)
    _lock_fd: int | None = field(default=None, init=False, repr=False)

    @property
    def runs_csv(self) -> Path:
        """The tidy per-step rows."""
        return self.path / RUNS

    @property
    def config_json(self) -> Path:
        """The settings, seed and versions."""
        return self.path / CONFIG

    def prepare(self) -> set[int]:
        """Create or reopen the folder; return the runs already complete. ValueError if it can't be used."""
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"cannot create output folder {self.path}: {exc.strerror or exc}; "
                             "expected a folder you can write to") from None
        self._lock()
        try:
            self.invocations = []
            if self.config_json.exists():
                self.invocations = self._check_same_settings()
            elif self.runs_csv.exists():
                raise ValueError(f"{self.runs_csv} exists but {self.config_json} does not, so its settings "
                                 "are unknown; expected a new folder or one this command wrote")
            self._write_config()
            done = self._complete_runs()
            self._rewrite(done)
        except BaseException:
            self.release()
            raise
        return set(done)

    def release(self) -> None:
        """Let other sweeps use the folder again."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the lock
            self._lock_fd = None

    def _lock(self) -> None:
        """Hold an exclusive lock on the folder, so two sweeps never append to one runs.csv."""
        if fcntl is None:  # not POSIX: no advisory locks; the user must not run two sweeps at once
            return
        # The lock is on the folder itself: no lock file to leave behind, and the OS drops it
        # when the process dies, so a crashed sweep never blocks its own resume.
        self._lock_fd = os.open(self.path, os.O_RDONLY)
        try:
            fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.release()
            raise ValueError(f"another sweep is writing to {self.path}; wait for it to finish or "
                             "stop it first (an interrupted sweep resumes when rerun)") from None

    def record_invocation(self, invocation: dict[str, Any]) -> None:
        """Add how this invocation ran (workers, wall time, runs computed, versions) to config.json."""
        self.invocations.append({**invocation, "versions": versions()})
        self._write_config()

    def _write_config(self) -> None:
        """Write config.json: the settings (all the numbers depend on), versions and every invocation."""
        config = {"settings": self.settings.to_json(), "versions": versions(), "invocations": self.invocations}
        try:
            _write_atomic(self.config_json, json.dumps(config, indent=2) + "\n")
        except OSError as exc:
            raise ValueError(f"cannot write {self.config_json}: {exc.strerror or exc}; "
                             "expected a folder you can write to") from None

    def append(self, rows: Iterable[list[Any]]) -> None:
        """Append one run's rows in a single write and flush them to disk."""
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerows(format_row(r) for r in rows)
        with open(self.runs_csv, "a", encoding="utf-8") as f:
            f.write(buffer.getvalue())
            f.flush()
            os.fsync(f.fileno())

    def finish(self) -> None:
        """Sort runs.csv (rows of complete runs only), making it independent of completion order."""
        self._rewrite(self._complete_runs())

    def read_rows(self) -> list[dict[str, str]]:
        """Every row of runs.csv as a dict of strings."""
        with open(self.runs_csv, encoding="utf-8", newline="") as f:
            return list(csv.DictReader(f))

    # ------------------------------------------------------------ internals

    def _check_same_settings(self) -> list[dict[str, Any]]:
        """Refuse a folder written with other settings; return its earlier invocations."""
        try:
            config = json.loads(self.config_json.read_text(encoding="utf-8"))
            stored = {**SIZE_DEFAULTS, **config["settings"]}
            invocations = list(config.get("invocations", []))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"{self.config_json} is not a sweep config this command wrote ({exc}); "
                             "expected a new folder or one this command wrote") from None
        current = self.settings.to_json()
        try:  # a folder written before a setting existed holds that setting's default
            stored = ExperimentSettings.from_json(stored).to_json()
        except ValueError:
            pass
        differences = [
            f"{key}: {stored.get(key)!r} there, {current.get(key)!r} now"
            for key in sorted(set(stored) | set(current))
            if stored.get(key) != current.get(key)
        ]
        if differences:
            raise ValueError(
                f"{self.path} holds a sweep with different settings ({'; '.join(differences)}); "
                "to resume, repeat its settings, or write to a new --out folder"
            )
        return invocations

    def _complete_runs(self) -> dict[int, list[str]]:
        """Runs whose rows are all present, mapped to their CSV lines (sorted)."""
        if not self.runs_csv.exists():
            return {}
        text = self.runs_csv.read_text(encoding="utf-8")
        lines = text.split("\n")
        lines = lines[:-1]  # the piece after the last newline is empty, or a half-written row
        if not lines or lines[0] != ",".join(COLUMNS):
            if lines:
                raise ValueError(f"{self.runs_csv} does not start with the expected header {','.join(COLUMNS)}")
            return {}
        by_run: dict[int, dict[tuple[str, int, int], str]] = {}
        for line in lines[1:]:
            fields = next(csv.reader([line]), [])
            key = _row_key(fields, self.settings)
            if key is not None:
                by_run.setdefault(key[0], {})[key[1:]] = line
        wanted = expected_keys(self.settings)
        return {
            run: [rows[k] for k in sorted(rows, key=_sort_key)]
            for run, rows in by_run.items()
            if set(rows) == wanted
        }

    def _rewrite(self, runs: dict[int, list[str]]) -> None:
        body = "".join(line + "\n" for run in sorted(runs) for line in runs[run])
        try:
            _write_atomic(self.runs_csv, ",".join(COLUMNS) + "\n" + body)
        except OSError as exc:
            raise ValueError(f"cannot write {self.runs_csv}: {exc.strerror or exc}") from None


def _row_key(fields: list[str], settings: ExperimentSettings) -> tuple[int, str, int, int] | None:
    """(run, protocol, n_query, n_executions) of a well-formed row of these settings, else None."""
    if len(fields) != len(COLUMNS):
        return None
    try:
        key = (int(fields[_COL["run"]]), fields[_COL["protocol"]], int(fields[_COL["n_query"]]),
               int(fields[_COL["n_executions"]]))
        for name in FLOAT_COLUMNS:
            float(fields[_COL[name]])
    except ValueError:
        return None
    same = (fields[_COL["seed"]] == str(settings.seed) and fields[_COL["domain"]] == settings.domain
            and fields[_COL["prior"]] == settings.prior and 0 <= key[0] < settings.runs)
    return key if same else None


def _sort_key(key: tuple[str, int, int]) -> tuple[int, int, int]:
    protocol, n_query, n_executions = key
    return PROTOCOLS.index(protocol) if protocol in PROTOCOLS else len(PROTOCOLS), n_query, n_executions


def _write_atomic(path: Path, text: str) -> None:
    """Write a file so that readers see the old or the new content, never a mix."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
