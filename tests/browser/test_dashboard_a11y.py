"""The dashboard passes axe-core (WCAG 2 A and AA rules) with no serious or critical violation on any screen,
and its statistics, archive and confirmation controls work in real Chromium."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tableteach.client import ExperimenterClient, run_teacher  # noqa: E402
from tests.browser.accessibility import axe_source  # noqa: E402
from tests.browser.conftest import LiveServer  # noqa: E402
from tests.web.conftest import EXPERIMENTER_TOKEN, study_spec  # noqa: E402

from tests.browser.test_dashboard import log_in  # noqa: E402

@pytest.fixture
def trace_server(tmp_path: Path) -> Any:
    """The app with the trace robot, served in a thread (quick to start on a busy machine)."""
    server = LiveServer(tmp_path, robot="trace").start()
    try:
        yield server
    finally:
        server.stop()


OUT = Path(__file__).resolve().parents[2] / "out" / "a11y"


def axe_problems(page: Any) -> list[str]:
    """Serious and critical axe-core violations of the page as it is now, one line each."""
    page.evaluate(axe_source())  # through the DevTools protocol: the page's CSP allows no inline script
    result = page.evaluate("""async () => {
        const r = await axe.run(document, {runOnly: {type: 'tag', values: ['wcag2a', 'wcag2aa', 'wcag21aa']}});
        return r.violations.filter(v => v.impact === 'serious' || v.impact === 'critical')
            .map(v => `${v.id} (${v.impact}): ${v.nodes.length} node(s): ` + v.nodes.slice(0, 4)
                .map(n => `${n.target.join(' ')} [${(n.any[0] || n.all[0] || {}).message || ''}]`).join('; '));
    }""")
    return list(result)


@pytest.mark.browser
def test_every_dashboard_screen_passes_axe_core(trace_server: Any, browser_page: Any) -> None:
    server = trace_server
    exp = ExperimenterClient(server.url, token=EXPERIMENTER_TOKEN)
    study = exp.create_study(study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=1,
                                        completion_code="DONE1", timeout_minutes=30))["id"]
    exp.open_study(study)
    run = run_teacher(server.url, study, ["task1"], seed=1, prolific_pid="PA11Y")
    run_teacher(server.url, study, ["task1"], seed=2, stop_after=3)
    page = browser_page
    OUT.mkdir(parents=True, exist_ok=True)
    problems: dict[str, list[str]] = {}
    for width, height in ((1366, 768), (390, 844)):
        page.set_viewport_size({"width": width, "height": height})
        page.goto(f"{server.url}/dashboard")
        page.evaluate("sessionStorage.clear()")  # logged out
        page.reload()
        page.wait_for_selector("form.login")
        assert page.locator("#logout").is_hidden()  # no "Log out" before logging in
        problems[f"login {width}"] = axe_problems(page)
        log_in(page, server.url, EXPERIMENTER_TOKEN)
        screens = [("studies", "#studies"), ("new", "#create"),
                   (f"study/{study}", "#statistics table"), (f"study/{study}/edit", "#create"),
                   (f"study/{study}/p/{run.participant_id}", "dl.facts"),
                   (f"study/{study}/prolific", "#reconciliation"), ("accounts", "#people-empty"),
                   ("account", "#server-key-note")]
        for route, ready in screens:
            page.goto(f"{server.url}/dashboard#/{route}")
            page.wait_for_selector(ready)
            page.wait_for_timeout(300)
            page.screenshot(path=str(OUT / f"{route.replace('/', '-')}-{width}.png"), full_page=True)
            problems[f"{route} {width}"] = axe_problems(page)
    (OUT / "axe.json").write_text(json.dumps(problems, indent=2))
    assert not {k: v for k, v in problems.items() if v}, problems


@pytest.mark.browser
def test_statistics_archive_and_confirmations_in_the_dashboard(trace_server: Any, browser_page: Any) -> None:
    server = trace_server
    exp = ExperimenterClient(server.url, token=EXPERIMENTER_TOKEN)
    study = exp.create_study(study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0))["id"]
    exp.open_study(study)
    run_teacher(server.url, study, ["task1"], seed=3)
    page = browser_page
    page.set_viewport_size({"width": 1366, "height": 768})
    log_in(page, server.url, EXPERIMENTER_TOKEN)
    page.goto(f"{server.url}/dashboard#/study/{study}")
    page.wait_for_selector("#funnel")
    assert "completed the study" in page.text_content("#funnel") and "median" in page.text_content(
        "#completion-times")
    asked: list[str] = []
    page.once("dialog", lambda dialog: (asked.append(dialog.message), dialog.dismiss()))
    page.click("#close-study")
    page.wait_for_timeout(300)
    assert "New participants can no longer join" in asked[0] and exp.get_study(study)["status"] == "open"
    page.once("dialog", lambda dialog: dialog.accept())
    page.click("#archive-study")
    page.wait_for_selector("#unarchive-study")
    assert exp.get_study(study)["archived_at"] and study not in [s["id"] for s in exp.list_studies()]
    page.goto(f"{server.url}/dashboard#/")
    page.wait_for_selector("#toggle-archived")
    assert study not in page.text_content("#app")
    page.click("#toggle-archived")
    page.wait_for_selector(f"text={study}")
    page.goto(f"{server.url}/dashboard#/study/{study}")
    page.wait_for_selector("#unarchive-study")
    page.once("dialog", lambda dialog: dialog.accept())
    page.click("#delete-study")
    # the archive's "Study archived" toast may still be up: wait for the refusal's own words
    page.wait_for_function("() => !document.querySelector('#toast').hidden"
                           " && document.querySelector('#toast').textContent.includes('archive it instead')")
    assert exp.get_study(study)["archived_at"]  # refused: the study and its participant are still there


SLOW_STUDY_LIST = """() => {
  const original = window.fetch;
  window.slowListsDone = 0;
  window.fetch = (input, init) => String(input).includes("/studies?include_archived")
    ? new Promise((done) => setTimeout(done, 1500)).then(() => original(input, init))
        .finally(() => { window.slowListsDone += 1; })
    : original(input, init);
}"""


@pytest.mark.browser
def test_a_view_that_loads_slowly_never_replaces_the_one_asked_for_after_it(trace_server: Any,
                                                                            browser_page: Any) -> None:
    server = trace_server
    exp = ExperimenterClient(server.url, token=EXPERIMENTER_TOKEN)
    study = exp.create_study(study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0))["id"]
    page = browser_page
    log_in(page, server.url, EXPERIMENTER_TOKEN)
    page.wait_for_selector("#toggle-archived")
    page.evaluate(SLOW_STUDY_LIST)
    # the study list is asked for first and answers last; the study page, asked for after it, must stay
    page.evaluate(f"() => {{ location.hash = '#/audit'; setTimeout(() => {{ location.hash = '#/'; }}, 50);"
                  f" setTimeout(() => {{ location.hash = '#/study/{study}'; }}, 300); }}")
    page.wait_for_function("() => window.slowListsDone >= 1", timeout=60_000)
    page.wait_for_selector("#funnel", timeout=60_000)
    page.wait_for_timeout(500)  # a stale view would replace it now, if it were going to
    assert page.locator("#funnel").count() == 1 and page.locator("#toggle-archived").count() == 0
