"""Screenshots of each page of the web UI for docs/ui.md, taken the way the browser tests drive it (Debian's
Chromium under Playwright, a real ``isolab serve`` on loopback with a fresh store).

    .venv/bin/python -m tests.browser.screenshots            # writes docs/ui-*.png
    .venv/bin/python -m tests.browser.screenshots --out /tmp/shots
    .venv/bin/python -m tests.browser.screenshots --scene   # only the scene page's

A full-page shot taller than ``MAX_HEIGHT`` is cut at the bottom of the part of the page it shows
(:func:`shot_down_to`), so each file stays a few hundred kB.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ui_driver import CHROMIUM, browser, service, submit_example, wait_done  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
VIEWPORT = {"width": 1300, "height": 900}
MAX_HEIGHT = 2500
"""Tallest shot, in CSS pixels."""


def take(out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    shots: list[Path] = []

    def shot(page, name: str, full: bool = True) -> None:
        page.wait_for_timeout(400)  # let Plotly finish its transitions
        path = out / f"ui-{name}.png"
        page.screenshot(path=str(path), full_page=full)
        shots.append(path)

    with (
        tempfile.TemporaryDirectory(prefix="isolab-shots-") as tmp,
        service(Path(tmp)) as svc,
        browser() as b,
    ):
        base = svc.url
        page = b.new_page(viewport=VIEWPORT)
        study_id = submit_example(page, base)
        wait_done(page)
        page.select_option("#colour", "isolator_type")
        shot(page, "study")

        page.goto(f"{base}/ui/studies/{study_id}/cases/7")
        page.wait_for_selector("#traces svg.main-svg", timeout=60_000)
        shot(page, "case")

        page.goto(f"{base}/ui/new")
        page.wait_for_selector("#source option[value='example:isolator-comparison']", state="attached")
        page.select_option("#source", "example:isolator-comparison")
        page.wait_for_selector("#check.ok")
        text = (
            page.input_value("#text").replace("num: 4", "num: 0").replace("mass: 1000 kg", "mass: -1000 kg")
        )
        page.fill("#text", text)
        page.wait_for_selector("#check.error")
        page.evaluate("document.querySelector('#text').scrollTop = 260")
        page.dispatch_event("#text", "scroll")
        shot(page, "new", full=False)

        # the scriber's criteria under each type: the answer in words, the margins, the floor view
        page.goto(f"{base}/ui/compare")
        page.wait_for_selector("#source option[value='example:scriber-criteria']", state="attached")
        page.select_option("#source", "example:scriber-criteria")
        page.click("#run")
        page.wait_for_selector("#floor-plot-camera .main-svg", timeout=90_000)
        shots.append(shot_down_to(page, out / "ui-compare.png", "#floor-card"))

        api = httpx.Client(base_url=base, timeout=60.0)
        shots.extend(optimisation_shots(page, api, base, out))
        shots.append(calibration_shot(page, base, out))
        shots.extend(scene_shots(page, base, out))

        # a sampled study with a log-sampled parameter: the sweep plot's log axis
        lhs = api.get("/examples/lhs-10000").json()["text"]
        small = lhs.replace("samples: 10000", "samples: 300").replace("name: lhs-10000", "name: lhs-300")
        sampled = submit_text(api, small)
        deadline = time.monotonic() + 120
        while api.get(f"/studies/{sampled}").json()["status"] != "done":
            assert time.monotonic() < deadline, "the sampled study did not finish"
            time.sleep(0.5)
        page.goto(f"{base}/ui/studies/{sampled}")
        wait_done(page)
        zeta = page.eval_on_selector(
            "#colour", "s => [...s.options].map(o => o.value).find(v => /zeta/.test(v))"
        )
        page.select_option("#colour", zeta)
        page.locator("#sweep-card").scroll_into_view_if_needed()
        page.locator("#sweep-card").screenshot(path=str(out / "ui-sweep-log.png"))
        shots.append(out / "ui-sweep-log.png")

        # the catalog while a large study runs (cancelled afterwards)
        running = submit_text(api, lhs)
        page.goto(f"{base}/ui/")
        page.wait_for_selector(f"#study-table tr[data-id='{running}'] .status-running", timeout=60_000)
        deadline = time.monotonic() + 60
        while api.get(f"/studies/{running}").json()["progress"]["done"] == 0 and time.monotonic() < deadline:
            time.sleep(0.5)
        page.wait_for_timeout(2000)  # the page's next refresh
        shot(page, "studies", full=False)
        api.delete(f"/studies/{running}")
    return shots


def shot_down_to(page, path: Path, selector: str) -> Path:
    """The page from its top down to the bottom of ``selector`` (at most ``MAX_HEIGHT`` px)."""
    page.wait_for_timeout(400)  # let Plotly finish its transitions
    bottom = page.eval_on_selector(selector, "n => n.getBoundingClientRect().bottom + window.scrollY")
    height = min(MAX_HEIGHT, int(bottom) + 16)
    page.screenshot(
        path=str(path), full_page=True, clip={"x": 0, "y": 0, "width": VIEWPORT["width"], "height": height}
    )
    return path


def wait_study(api: httpx.Client, study_id: str, timeout_s: float = 110.0) -> None:
    deadline = time.monotonic() + timeout_s
    while (status := api.get(f"/studies/{study_id}").json()["status"]) in ("queued", "running"):
        assert time.monotonic() < deadline, f"study {study_id} still {status}"
        time.sleep(0.5)
    assert status == "done", status


def optimisation_shots(page, api: httpx.Client, base: str, out: Path) -> list[Path]:
    """A short run of the tune-air-mounts example (3 generations of 8): its study page's answer (progress,
    best design, margins, floor view of the best case) and its design report."""
    text = api.get("/examples/tune-air-mounts").json()["text"]
    text = re.sub(r"budget: \d+", "budget: 24", text).replace("population: 40", "population: 8")
    study_id = submit_text(api, text)
    wait_study(api, study_id)
    page.goto(f"{base}/ui/studies/{study_id}")
    page.wait_for_selector("#best-parameters", timeout=60_000)
    page.wait_for_selector("#progress svg.main-svg", timeout=30_000)
    page.wait_for_selector("#floor-plot-tool .main-svg", timeout=60_000)
    page.wait_for_timeout(400)
    answer = out / "ui-optimisation.png"
    page.locator("#answer-card").screenshot(path=str(answer))
    page.goto(f"{base}/studies/{study_id}/report.html", timeout=90_000)
    page.wait_for_selector("h1", timeout=90_000)
    return [answer, shot_down_to(page, out / "ui-report.png", "body")]


def calibration_shot(page, base: str, out: Path) -> Path:
    """The shipped calibration example started from /ui/calibrate: its fit, once done."""
    from isolab.service.api.schemas import EXAMPLE_CALIBRATION
    from isolab.studies.answers.calibration import measurement_csv, measurement_from_columns

    m = EXAMPLE_CALIBRATION["measurement"]
    with tempfile.TemporaryDirectory(prefix="isolab-calibration-") as tmp:
        scene, csv = Path(tmp) / "scene.json", Path(tmp) / "tracker.csv"
        scene.write_text(json.dumps(EXAMPLE_CALIBRATION["scene"]))
        csv.write_text(measurement_csv(measurement_from_columns(m["time"], m["channels"])))
        page.goto(f"{base}/ui/calibrate")
        page.set_input_files("#scene-file", str(scene))
        page.set_input_files("#measurement-file", str(csv))
        page.fill("#fit", "isolators.f_horizontal=1 Hz:6 Hz")
        page.click("#calibrate")
        page.wait_for_url(re.compile(r"/ui/calibrations/[0-9a-f]{32}$"), timeout=30_000)
    page.wait_for_selector("#fitted-table", timeout=110_000)
    page.wait_for_selector("#traces-plot svg.main-svg", timeout=30_000)
    return shot_down_to(page, out / "ui-calibration.png", "#traces-card")


def scene_shots(page, base: str, out: Path) -> list[Path]:
    """The scene page on the article's scriber: its top with the 3D view (:func:`scene_shot`), the run's
    answer and traces, its plan view, and the Y stage's form with the plot of its profile."""
    top = scene_shot(page, base, out)
    run = out / "ui-scene-run.png"
    page.locator("#traces").locator("xpath=..").screenshot(path=str(run))
    plan = out / "ui-scene-plan.png"
    page.locator("#plan").locator("xpath=..").screenshot(path=str(plan))
    profile = out / "ui-scene-profile.png"
    page.locator("#profile-plot-0").locator("xpath=..").screenshot(path=str(profile))
    return [top, run, plan, profile]


def scene_shot(page, base: str, out: Path) -> Path:
    """The scene page on the article's scriber down to its 3D view: run twice (stiffer mounts the second
    time), the 3D view paused during the playback of the run."""
    page.goto(f"{base}/ui/scene?example=article-scriber")
    page.wait_for_selector("#base-mass", timeout=60_000)
    page.click("#run")
    page.wait_for_selector("#traces[data-runs='1']", timeout=60_000)
    page.fill('input[data-path=\'["isolators","f_vertical"]\']', "5 Hz")
    page.wait_for_selector("#run:not([disabled])", timeout=60_000)
    page.click("#run")
    page.wait_for_selector("#traces[data-runs='2']", timeout=60_000)
    page.fill("#exaggeration", "100")
    page.eval_on_selector("#time", "s => { s.value = '320'; s.dispatchEvent(new Event('input')); }")
    page.wait_for_timeout(600)
    return shot_down_to(page, out / "ui-scene.png", "#view3d")


def submit_text(api: httpx.Client, text: str) -> str:
    """Check a study text and submit its definition, as the page does; the new study's id."""
    checked = api.post("/studies/validate", json={"text": text})
    checked.raise_for_status()
    accepted = api.post("/studies", json=checked.json()["definition"])
    accepted.raise_for_status()
    return str(accepted.json()["id"])


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="folder for the PNG files")
    parser.add_argument("--scene", action="store_true", help="only the scene page's shots")
    args = parser.parse_args()
    if not CHROMIUM.exists():
        sys.exit(f"no {CHROMIUM}: run `make browser` first")
    for path in take_scene(args.out) if args.scene else take(args.out):
        print(path)


def take_scene(out: Path) -> list[Path]:
    """Only the scene page's shots (:func:`scene_shots`)."""
    out.mkdir(parents=True, exist_ok=True)
    with (
        tempfile.TemporaryDirectory(prefix="isolab-shots-") as tmp,
        service(Path(tmp)) as svc,
        browser() as b,
    ):
        return scene_shots(b.new_page(viewport=VIEWPORT), svc.url, out)


if __name__ == "__main__":
    main()
