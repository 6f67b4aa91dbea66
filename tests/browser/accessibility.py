"""axe-core in the browser tests: the engine from the npm registry (package.json; scripts/test.sh runs npm ci),
evaluated in the page under test, which reports every serious or critical violation of a screen."""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
AXE_JS = Path(os.environ.get("TABLETEACH_AXE_JS") or ROOT / "node_modules" / "axe-core" / "axe.min.js")
SERIOUS = ("serious", "critical")
# viser's client in the 3D view's frame is not this project's page (and axe would need injecting into it).
RUN = """async () => {
  const result = await axe.run({ exclude: [['#viewer-frame']] }, { resultTypes: ['violations'] });
  return result.violations.map(v => ({ id: v.id, impact: v.impact, help: v.help,
    nodes: v.nodes.slice(0, 3).map(n => n.target.join(' ')) }));
}"""


@lru_cache(maxsize=1)
def axe_source() -> str:
    """axe.min.js; a skip (a failure with CI=true) when it is not installed."""
    if not AXE_JS.is_file():
        message = f"{AXE_JS} not found: run scripts/test.sh (it installs axe-core with npm ci)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)
    return AXE_JS.read_text(encoding="utf-8")


def serious_violations(page) -> list[dict]:
    """The screen's serious and critical axe-core violations. The engine is evaluated through the browser's
    devtools protocol, which the page's Content-Security-Policy (scripts from this server only) does not cover."""
    if not page.evaluate("() => typeof axe !== 'undefined'"):
        page.evaluate(axe_source() + "\n;0")
    return [v for v in page.evaluate(RUN) if v["impact"] in SERIOUS]


def assert_accessible(page, screen: str) -> None:
    """No serious or critical axe-core violation on this screen."""
    found = serious_violations(page)
    assert not found, f"axe-core on the {screen} screen: {found}"
