"""The house's seams, checked on the source: a pure core, simulation imported by the composition root only, no
upward imports from the database adapter, and threads started only where docs/concurrency.md lists them."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

BACKEND = Path(__file__).resolve().parents[1] / "backend"
STDLIB = set(sys.stdlib_module_names)


def _imports(path: Path) -> list[tuple[str, int]]:
    """Every module a file imports (function-level imports too), as absolute tableteach.* or top-level names."""
    package = ["tableteach", *path.relative_to(BACKEND).with_suffix("").parts[:-1]]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
                names = [name] if node.module else [f"{name}.{alias.name}" for alias in node.names]
            else:
                names = [node.module or ""]
            out += [(name, node.lineno) for name in names]
    return out


def _files(folder: str = "") -> list[Path]:
    return sorted((BACKEND / folder).rglob("*.py"))


def test_the_core_imports_only_the_standard_library_and_numpy() -> None:
    bad = [f"{p.relative_to(BACKEND)}:{line} imports {name}" for p in _files("core") for name, line in _imports(p)
           if not (name.split(".")[0] in STDLIB or name.split(".")[0] == "numpy"
                   or name.startswith("tableteach.core"))]
    assert bad == []


def test_only_the_composition_root_imports_the_simulation() -> None:
    allowed = {BACKEND / "web" / "robots.py"}
    bad = [f"{p.relative_to(BACKEND)}:{line} imports {name}" for p in _files() for name, line in _imports(p)
           if name.startswith("tableteach.sim") and p not in allowed and "sim" not in p.relative_to(BACKEND).parts]
    assert bad == []


def test_the_database_adapter_never_imports_the_services_or_the_web() -> None:
    bad = [f"{p.relative_to(BACKEND)}:{line} imports {name}" for p in _files("db") for name, line in _imports(p)
           if name.startswith(("tableteach.services", "tableteach.web", "tableteach.sim"))]
    assert bad == []


THREAD_OWNERS = {  # docs/concurrency.md lists each
    "services/runtime.py",  # job runners, scheduler, action queue
    "sim/robot.py",  # the animator, started by the runtime through Robot.start
    "db/pg_notify.py",  # the LISTEN thread of the PostgreSQL notifier
    "experiments/executors.py",  # the offline sweep's process pool (no server)
    "sim/session.py",  # SceneSession, a standalone scene runner for tools and notebooks (the server never uses it)
}


def test_threads_are_started_only_by_the_owners_docs_concurrency_lists() -> None:
    starters = ("Thread", "Timer", "ThreadPoolExecutor", "ProcessPoolExecutor")
    found = set()
    for path in _files():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                func = node.func
                name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                if name in starters:
                    found.add(path.relative_to(BACKEND).as_posix())
    assert found <= THREAD_OWNERS, sorted(found - THREAD_OWNERS)
