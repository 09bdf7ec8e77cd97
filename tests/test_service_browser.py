"""The viewer in a real headless browser: Debian's chromium driven by Playwright's Python
package (Playwright's own browser download is not used). A service with a token runs on
loopback; the page takes the token, submits the paper's scene through its file input, follows
the job's events to the top rung and animates the plan. The drawing is checked structurally
(pixels of each role's colour, the animation's time moving), not pixel for pixel.

Not skipped when chromium is missing: `make test` installs it (apt-get), and this test fails
saying how to, so the browser is never silently left untested."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from tests.conftest import SCENARIOS
from tests.service_server import JOB_TIMEOUT_S, cli_plan_json, running_service

CHROMIUM = Path(os.environ.get("LADDER_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
#: The page's colours per role (static/index.html COLOURS), as RGB.
ROBOT, OBJECT = (0xE8, 0x74, 0x3B), (0x4A, 0x7E, 0xBB)

COUNT_PIXELS = """([robot, object]) => {
  const canvas = document.getElementById("view");
  const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
  const near = (i, c) => Math.abs(data[i] - c[0]) < 8 && Math.abs(data[i + 1] - c[1]) < 8 && Math.abs(data[i + 2] - c[2]) < 8;
  let drawn = 0, robots = 0, objects = 0;
  for (let i = 0; i < data.length; i += 4) {
    if (data[i + 3] === 0) continue;
    drawn++;
    if (near(i, robot)) robots++;
    if (near(i, object)) objects++;
  }
  return { drawn, robots, objects, total: data.length / 4 };
}"""


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.fail(
            f"the browser test needs Debian's chromium at {CHROMIUM}: `make test` installs it as root, "
            "or run `apt-get install chromium` (or set LADDER_CHROMIUM to a chromium binary)",
            pytrace=False,
        )
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield browser
        browser.close()


def test_the_viewer_submits_the_paper_scene_follows_it_and_animates_the_plan(browser, tmp_path):
    timeout_ms = JOB_TIMEOUT_S * 1000
    with running_service(tmp_path / "jobs.sqlite", workers=1, token="s3cret") as url:
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.goto(url + "/")
        assert page.title() == "ladder: planning service"
        page.fill("#token", "s3cret")
        page.click("#save-token")
        page.set_input_files("#file", str(SCENARIOS / "two_finger_triangle.toml"))
        page.fill("#params", "v1=0.8")
        page.fill("#options", json.dumps({"seed": 2}))
        page.click("#submit")

        page.wait_for_selector("#job-state.succeeded", timeout=timeout_ms)
        # the state may show before the event stream delivers the job's last event
        page.wait_for_function("document.querySelector('#log').innerText.includes('job_ended: succeeded')", timeout=timeout_ms)
        log = page.inner_text("#log")
        assert "state: running" in log and "rung_started: dynamic-compliant" in log and "job_ended: succeeded" in log
        assert "rung_ended: dynamic-compliant" in log  # the top rung, followed live through the events
        ids = [int(line.split()[0]) for line in log.splitlines() if line.strip()]
        assert ids == sorted(ids) and len(set(ids)) == len(ids)
        # the jobs table redraws after the job's end arrives (its refresh is asynchronous)
        page.wait_for_function("document.querySelector('#jobs tr.job td.succeeded') !== null", timeout=timeout_ms)
        assert page.locator("#jobs tr.job").count() == 1 and "succeeded" in page.inner_text("#jobs tr.job")

        page.wait_for_function("document.querySelectorAll('#rung option').length === 4", timeout=timeout_ms)
        rungs = page.eval_on_selector_all("#rung option", "options => options.map(o => o.textContent)")
        assert [r.split()[0] for r in rungs] == ["geometric", "kinematic", "quasistatic-rigid", "dynamic-compliant"]
        assert page.eval_on_selector("#rung", "s => s.selectedOptions[0].textContent").startswith("dynamic-compliant")

        page.wait_for_function("Number(document.getElementById('view').dataset.drawn) > 5", timeout=timeout_ms)
        first = page.input_value("#frame"), page.inner_text("#frame-label"), int(page.get_attribute("#view", "data-drawn"))
        moved = f"document.getElementById('frame').value !== '{first[0]}' && Number(document.getElementById('view').dataset.drawn) > "
        page.wait_for_function(moved + str(first[2]), timeout=timeout_ms)
        assert page.inner_text("#frame-label") != first[1] and "state" in first[1]
        pixels = page.evaluate(COUNT_PIXELS, [ROBOT, OBJECT])
        assert 0.05 * pixels["total"] < pixels["drawn"] < pixels["total"]  # the palm, the triangle, the fingers, not all of it
        assert pixels["objects"] > 1000 and pixels["robots"] > 20  # the triangle (2 m wide) and two fingers (0.1 m)

        page.click("#play")  # paused: the slider scrubs through the plan
        page.fill("#frame", "0")
        page.dispatch_event("#frame", "input")
        page.wait_for_function("document.getElementById('frame-label').textContent.startsWith('t = 0.00 /')", timeout=timeout_ms)
        assert page.inner_text("#play") == "play"
        page.screenshot(path=str(tmp_path / "viewer.png"), full_page=True)
        assert (tmp_path / "viewer.png").stat().st_size > 10_000
        assert errors == []

        from planner.service.client import Client

        with Client(url, token="s3cret") as client:
            (job,) = client.jobs()
            assert job["filename"] == "two_finger_triangle.toml" and job["parameters"] == {"v1": 0.8}
            served = json.loads(client.result(job["id"]))
        expected = json.loads(cli_plan_json(SCENARIOS / "two_finger_triangle.toml", seed=2, parameters={"v1": 0.8}))
        assert served["rungs"] == expected["rungs"] and served["top_holds"] is True


def test_the_viewer_draws_a_spatial_scene_from_above_and_a_sweeps_outcomes(browser, tmp_path, monkeypatch):
    """box_push_3d (boxes, a sphere, a convex mesh, the table) seen from above, at its start (a
    service that runs no job), and a sweep's outcomes over its grid."""
    from planner.service.client import Client

    monkeypatch.chdir(SCENARIOS.parent)
    with running_service(tmp_path / "jobs.sqlite", workers=0) as url:
        with Client(url) as client:
            job = client.submit("scenarios/box_push_3d.toml")  # carries meshes/wedge.obj
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.goto(url + "/")
        page.click(f"#jobs tr.job[data-id='{job['id']}']")
        page.wait_for_selector("#job-state.queued")
        page.evaluate(f"async () => startAnimation(await (await api('/jobs/{job['id']}/scene')).json())")
        page.wait_for_function("Number(document.getElementById('view').dataset.drawn) > 0")
        floor, obstacle = (0xF1, 0xED, 0xE4), (0x9A, 0x9A, 0x9A)
        pixels = page.evaluate(COUNT_PIXELS, [ROBOT, OBJECT])
        table = page.evaluate(COUNT_PIXELS, [floor, obstacle])
        assert pixels["objects"] > 1000 and pixels["robots"] > 50  # the 0.2 m box, the 0.03 m sphere
        assert table["robots"] > 0.5 * pixels["total"] and table["objects"] > 1000  # the table under all, the wall and the wedge
        page.screenshot(path=str(tmp_path / "viewer-3d.png"), full_page=True)
        # a rung with no states (omitted, skipped) shows the bodies at their start and the animation goes on:
        # its times had one entry and its placements none, and the page stopped drawing at the first frame
        empty = {"rung": "kinematic", "label": "kinematic", "ended": "omitted", "outcome": "none", "times": [], "placements": []}
        page.evaluate(
            f"async (empty) => {{ const scene = await (await api('/jobs/{job['id']}/scene')).json(); "
            "scene.rungs = [empty]; startAnimation(scene); }",
            empty,
        )
        before = page.evaluate("Number(document.getElementById('view').dataset.drawn)")
        page.wait_for_function(f"Number(document.getElementById('view').dataset.drawn) > {before + 5}", timeout=10_000)
        assert page.evaluate(COUNT_PIXELS, [ROBOT, OBJECT])["objects"] > 1000 and errors == []

        sweep = {
            "axes": [{"name": "v1", "values": [0.25, 1.0, 4.0], "log": True}],
            "models": ["kinematic", "plastic"],
            "points": [
                {"model": m, "parameters": {"v1": v}, "outcome": outcome}
                for m, outcomes in (("kinematic", ("unsafe", "goal", "goal")), ("plastic", ("unsafe", "goal", "none")))
                for v, outcome in zip((0.25, 1.0, 4.0), outcomes)
            ],
        }
        draws = "sweep => { anim = null; const view = document.getElementById('view'), before = Number(view.dataset.drawn); "
        draws += "drawSweep(sweep); return Number(view.dataset.drawn) - before; }"
        assert page.evaluate(draws, sweep) == 1  # the plan's animation stopped, the sweep drawn once
        goal, unsafe = (0x2C, 0xA0, 0x2C), (0xD6, 0x27, 0x28)
        dots = page.evaluate(COUNT_PIXELS, [goal, unsafe])
        assert 1.3 < dots["robots"] / dots["objects"] < 1.7  # 3 goal dots, 2 unsafe ones
        assert errors == []
        page.close()  # its EventSource follows a job that never ends
