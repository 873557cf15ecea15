"""The scene page in a real headless Chromium against a real ``isolab serve``: open the article's scriber,
read the base's computed mass, see a problem shown at its field, run the scene and read its Y peak, change
a mount frequency and see both runs overlaid, animate a mode and play the run back on the 3D view, export
the scene and hand it to a study.

``make browser`` installs Chromium where it is missing; without it these tests are skipped."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest
import yaml
from ui_driver import CHROMIUM, ConsoleErrors, overlapping, service, settle, wait_until

from tests.shared_cluster import shared_scheduler

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not CHROMIUM.exists(), reason=f"no {CHROMIUM}: `make browser` installs Debian's chromium"
    ),
]

VIEWPORT = {"width": 1400, "height": 1000}
WAIT_S = 60.0


def field(path: list) -> str:
    """The input of the scene form bound to ``path``."""
    return f"input[data-path='{json.dumps(path, separators=(',', ':'))}']"


@pytest.fixture(scope="module")
def base_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with service(tmp_path_factory.mktemp("scene"), scheduler=shared_scheduler(2)) as svc:
        yield svc.url


@pytest.fixture
def page(chromium, base_url: str) -> Iterator:
    context = chromium.new_context(viewport=VIEWPORT, accept_downloads=True)
    tab = context.new_page()
    # the service's 422 on a bad field is an answer the page shows at the field, not a failure
    tab.errors = ConsoleErrors(tab, ignore=("status of 422",))
    tab.requested = []
    tab.on("request", lambda r: tab.requested.append(r.url))
    yield tab
    context.close()


def base_z(page) -> list[float]:
    """The z of the base's eight corners as the 3D figure draws them now."""
    return page.evaluate("document.querySelector('#view3d').data[0].z")


def test_the_scriber_is_built_run_changed_and_animated(page, base_url: str) -> None:
    page.goto(f"{base_url}/ui/scene?example=article-scriber")
    wait_until(page, "document.querySelector('#base-mass') !== null", timeout_s=WAIT_S)
    # 2.6 x 4.2 x 0.34 m of granite at 2700 kg/m^3: 10,024.56 kg, computed by the service
    assert page.inner_text("#base-mass") == "10.02 t"
    assert "10024.6 kg" in page.inner_text("#base-computed")
    assert "Ixx 14830, Iyy 5744, Izz 20380 kg m²" in page.inner_text("#base-computed")  # m (ly²+lz²)/12...
    mounts = page.inner_text("#mount-table")
    for place in ("front-left", "front-right", "back-right", "back-left"):
        assert place in mounts
    # the 3D view: base, edges, mounts, seats, mount labels, travel, stages, points, c.g.
    names = page.evaluate("document.querySelector('#view3d').data.map(t => t.name)")
    assert names[0] == "base" and "stages" in names and "c.g." in names
    labels = page.evaluate("document.querySelector('#view3d').data[4].text")
    assert "mount_0 (front-left)" in labels
    travel = page.evaluate("document.querySelector('#view3d').data[5].y")
    assert pytest.approx(max(v for v in travel if v is not None) - 0.6) == 3.0  # the Y stage's 3 m scan

    # a problem is shown at its field, and clears
    page.fill(field(["machine", "block", "density"]), "-5")
    wait_until(page, "document.querySelector('.field.bad .field-error') !== null", timeout_s=WAIT_S)
    assert "greater than 0" in page.inner_text(".field.bad .field-error")
    assert page.is_disabled("#run")
    page.fill(field(["machine", "block", "density"]), "2700 kg/m^3")
    wait_until(page, "!document.querySelector('#run').disabled", timeout_s=WAIT_S)
    assert page.query_selector(".field.bad") is None

    # run it: the article's 5.67 mm of Y sway, in words
    page.click("#run")
    wait_until(page, "document.querySelector('#traces').dataset.runs === '1'", timeout_s=WAIT_S)
    assert page.inner_text(".peak[data-key='peak_displacement_y']") == "Y 5.67 mm"
    summary = page.inner_text("#summary")
    assert "heave" in summary and "3.5 Hz" in summary and "no isolator lifts off" in summary

    # stiffer mounts: run again, both runs drawn, the peak compared with the one before
    page.fill(field(["isolators", "f_vertical"]), "5 Hz")
    wait_until(page, "!document.querySelector('#run').disabled", timeout_s=WAIT_S)
    vertical = page.evaluate(
        "[...document.querySelectorAll('#mount-table tbody tr')].map(r => r.cells[4].textContent)"
    )
    assert vertical == ["5", "5", "5", "5"]  # the service's frequency of each mount on its static load
    page.click("#run")
    wait_until(page, "document.querySelector('#traces').dataset.runs === '2'", timeout_s=WAIT_S)
    peak = page.inner_text(".peak[data-key='peak_displacement_y']")
    assert peak.endswith("(was 5.67 mm)"), peak
    traces = page.evaluate("document.querySelector('#traces').data.map(t => t.name)")
    assert any("(run 1, before)" in n for n in traces) and any("(run 2)" in n for n in traces)
    assert len(traces) == 2 * (6 + 4)
    assert overlapping(page, "#traces g.infolayer text[class$='title']") == []  # the panels' axis titles

    # a mode moves the base
    rest = base_z(page)
    page.select_option("#mode", "0")  # heave
    page.click("#animate-mode")
    frames = []
    for _ in range(6):
        settle(0.15)
        frames.append(base_z(page))
    assert len({tuple(f) for f in frames}) > 2, "the heave mode does not move the base"
    assert all(f != rest for f in frames[1:])
    page.click("#animate-mode")

    # the run played back: the slider moves the base and the marker on the traces
    page.fill("#exaggeration", "100")
    page.evaluate(
        "(() => { const s = document.querySelector('#time'); s.value = '300'; "
        "s.dispatchEvent(new Event('input')); })()"
    )
    marker = page.evaluate("document.querySelector('#traces').layout.shapes[0].x0")
    assert marker > 0 and page.inner_text("#time-label").startswith("t = ")
    assert base_z(page) != rest
    page.click("#play")
    wait_until(page, "Number(document.querySelector('#time').value) > 300", timeout_s=10)
    page.click("#play")

    # export: the scene as YAML, and handed to a new study
    with page.expect_download() as got:
        page.click("#download-yaml")
    exported = yaml.safe_load(open(got.value.path(), encoding="utf-8").read())
    assert exported["machine"]["block"]["density"] == "2700 kg/m^3"
    assert exported["isolators"]["f_vertical"] == "5 Hz"
    page.click("#start-study")
    page.wait_for_url(f"{base_url}/ui/new?from=draft", timeout=WAIT_S * 1000)
    page.wait_for_selector("#check.ok", timeout=WAIT_S * 1000)
    assert "1 cases" in page.inner_text("#check") or "1 case" in page.inner_text("#check")
    assert not page.errors, page.errors
    foreign = [u for u in page.requested if not u.startswith((base_url, "blob:", "data:"))]
    assert not foreign, foreign


def test_an_empty_scene_opens_and_a_stored_study_s_scene_too(page, base_url: str) -> None:
    page.goto(f"{base_url}/ui/scene")
    wait_until(page, "document.querySelector('#base-mass') !== null", timeout_s=WAIT_S)
    assert page.inner_text("#base-mass") == "540 kg"  # 1 x 1 x 0.2 m at 2700 kg/m^3
    page.goto(f"{base_url}/ui/scene?study=0123456789abcdef0123456789abcdef")
    wait_until(page, "document.querySelector('#error .error') !== null", timeout_s=WAIT_S)
    assert "0123456789abcdef0123456789abcdef" in page.inner_text("#error")
    assert not [e for e in page.errors if "404" not in e], page.errors


def select(path: list) -> str:
    """The select of the scene form bound to ``path``."""
    return f"select[data-path='{json.dumps(path, separators=(',', ':'))}']"


def type_in(page, path: list, *values: str) -> None:
    """Type ``values`` into the field at ``path`` (one per box of a vector)."""
    if len(values) == 1:
        page.fill(field(path), values[0])
    else:
        for i, v in enumerate(values):
            page.fill(field([*path, i]), v)


def accepted(page) -> None:
    """Wait until the service has accepted the scene as it is typed now."""
    wait_until(
        page,
        "!document.querySelector('#run').disabled && "
        "document.querySelector('#check-status').className === 'ok'",
        timeout_s=WAIT_S,
    )


def test_the_article_s_scriber_is_typed_into_an_empty_builder_and_run(page, base_url: str) -> None:
    page.goto(f"{base_url}/ui/scene")
    wait_until(page, "document.querySelector('#base-mass') !== null", timeout_s=WAIT_S)
    assert page.inner_text("#base-mass") == "540 kg"
    # the base: 2.6 x 4.2 x 0.34 m of granite; the service computes its 10 t
    type_in(page, ["machine", "block", "size"], "2.6 m", "4.2 m", "0.34 m")
    type_in(page, ["machine", "block", "density"], "2700 kg/m^3")
    accepted(page)
    assert page.inner_text("#base-mass") == "10.02 t"
    assert "c.g. at (1.3, 2.1, 0.17) m" in page.inner_text("#base-computed")
    # four air mounts 2.2 x 3.6 m around the c.g., 0.5 m below it, at 3.5 Hz vertical and 5 Hz lateral
    page.select_option(select(["isolators", "preset"]), "air")
    type_in(page, ["isolators", "f_vertical"], "3.5 Hz")
    type_in(page, ["isolators", "f_horizontal"], "5 Hz")
    type_in(page, ["isolators", "layout", "span_x"], "2.2 m")
    type_in(page, ["isolators", "layout", "span_y"], "3.6 m")
    type_in(page, ["isolators", "layout", "height"], "0.5 m")
    accepted(page)
    # the plan view: the 2.6 x 4.2 m outline, each mount at its corner with its name
    plan = page.evaluate(
        "(() => { const d = document.querySelector('#plan').data; "
        "return {x: d[0].x, y: d[0].y, text: d[1].text, mx: d[1].x, my: d[1].y}; })()"
    )
    assert max(plan["x"]) == pytest.approx(2.6) and max(plan["y"]) == pytest.approx(4.2)
    assert plan["text"][0] == "mount_0 (front-left)" and plan["text"][2] == "mount_2 (back-right)"
    assert plan["mx"] == pytest.approx([0.2, 2.4, 2.4, 0.2]) and plan["my"] == pytest.approx(
        [0.3, 0.3, 3.9, 3.9]
    )

    # the Y stage: 1000 kg scanning 3 m at 2 m/s and 2 g, dwelling 0.2 s
    page.click("#forms button:has-text('Add stage')")
    type_in(page, ["stages", 0, "name"], "y")
    type_in(page, ["stages", 0, "mass"], "1000 kg")
    type_in(page, ["stages", 0, "home"], "1.3 m", "0.6 m", "0.47 m")
    type_in(page, ["stages", 0, "axis"], "0", "1", "0")
    page.select_option(select(["stages", 0, "profile", "type"]), "scan")
    for name, value in (
        ("travel", "3 m"),
        ("velocity", "2 m/s"),
        ("acceleration", "2 g"),
        ("dwell", "0.2 s"),
    ):
        type_in(page, ["stages", 0, "profile", name], value)
    type_in(page, ["stages", 0, "profile", "repeats"], "1")
    # the X stage riding on it: 100 kg, 0.3 m at 1 m/s and 1 g, from 1.65 s
    accepted(page)
    page.click("#forms button:has-text('Add stage')")
    type_in(page, ["stages", 1, "name"], "x")
    type_in(page, ["stages", 1, "parent"], "y")
    type_in(page, ["stages", 1, "mass"], "100 kg")
    type_in(page, ["stages", 1, "home"], "1.15 m", "0.6 m", "0.6 m")
    type_in(page, ["stages", 1, "axis"], "1", "0", "0")
    assert page.input_value(select(["stages", 1, "profile", "type"])) == "trapezoid"
    for name, value in (
        ("travel", "0.3 m"),
        ("velocity", "1 m/s"),
        ("acceleration", "1 g"),
        ("start", "1.65 s"),
    ):
        type_in(page, ["stages", 1, "profile", name], value)
    # the points of interest
    for name, where in (("tool", ("1.15 m", "0.6 m", "0.6 m")), ("camera", ("1.3 m", "3.6 m", "0.9 m"))):
        page.fill("input[aria-label='new point name']", name)
        page.click("#forms button:has-text('Add point')")
        type_in(page, ["points", name], *where)
    accepted(page)
    assert page.inner_text("#base-facts").startswith(
        "Base 10.02 t, with its stages 11.12 t: 4 mounts, 2 stages"
    )

    # each stage's profile as the service samples it: the Y scan out 3 m and back by 3.60 s
    y_plot = page.evaluate(
        "(() => { const d = document.querySelector('#profile-plot-0').data; "
        "return {s: Math.max(...d[0].y), v: Math.max(...d[1].y), a: Math.min(...d[2].y), "
        "end: Number(document.querySelector('#profile-plot-0').dataset.end)}; })()"
    )
    assert y_plot["s"] == pytest.approx(3000.0) and y_plot["v"] == pytest.approx(2.0)
    assert y_plot["a"] == pytest.approx(-2 * 9.80665)
    assert y_plot["end"] == pytest.approx(2 * (3 / 2 + 2 / (2 * 9.80665)) + 2 * 0.2, rel=1e-9)
    assert float(page.get_attribute("#profile-plot-1", "data-end")) == pytest.approx(1.65 + 0.3 + 1 / 9.80665)

    # run: the article's 5.67 mm of Y sway
    page.click("#run")
    wait_until(page, "document.querySelector('#traces').dataset.runs === '1'", timeout_s=WAIT_S)
    assert page.inner_text(".peak[data-key='peak_displacement_y']") == "Y 5.67 mm"

    # criteria and floor, checked as typed, each problem shown at its field
    def problem_at(path: list) -> str:
        wait_until(page, f"document.querySelector(`.field.bad {field(path)}`) !== null", timeout_s=WAIT_S)
        return page.inner_text(".field.bad .field-error")

    type_in(page, ["criteria", "tool", "displacement"], "-10 um")
    assert "greater than 0" in problem_at(["criteria", "tool", "displacement"])
    type_in(page, ["criteria", "tool", "displacement"], "10 mm")
    type_in(page, ["criteria", "tool", "velocity"], "VC-C")
    assert "needs the floor's vibration" in problem_at(["criteria", "tool", "velocity"])
    page.select_option(select(["floor", "spectrum", "z", "_kind"]), "vc")
    type_in(page, ["floor", "spectrum", "z"], "VC-Q")
    assert "unknown VC level 'VC-Q'" in problem_at(["floor", "spectrum", "z"])
    type_in(page, ["floor", "spectrum", "z"], "VC-D")
    page.check("#no-liftoff")
    type_in(page, ["criteria", "isolators", "max_force"], "40 kN")
    accepted(page)
    assert page.query_selector(".field.bad") is None

    # the comparison of types starts from this scene
    page.click("#compare-types")
    page.wait_for_url(f"{base_url}/ui/compare?from=draft", timeout=WAIT_S * 1000)
    page.wait_for_selector("#source option[value='draft:scene']", state="attached", timeout=WAIT_S * 1000)
    assert page.input_value("#source") == "draft:scene"
    handed = page.evaluate("JSON.parse(sessionStorage.getItem('isolab-draft-scene'))")
    assert handed["criteria"] == {
        "tool": {"displacement": "10 mm", "velocity": "VC-C"},
        "isolators": {"no_liftoff": True, "max_force": "40 kN"},
    }
    assert handed["floor"] == {"spectrum": {"z": "VC-D"}}
    assert handed["machine"]["block"]["size"] == ["2.6 m", "4.2 m", "0.34 m"]
    assert not page.errors, page.errors


def test_a_sequence_is_edited_move_by_move_and_a_mount_is_dragged_on_the_plan(page, base_url: str) -> None:
    page.goto(f"{base_url}/ui/scene")
    wait_until(page, "document.querySelector('#base-mass') !== null", timeout_s=WAIT_S)
    page.click("#forms button:has-text('Add stage')")
    page.select_option(select(["stages", 0, "profile", "type"]), "sequence")
    page.click("#forms button:has-text('Add dwell')")
    page.click("#forms button:has-text('Add move')")
    segments = ["stages", 0, "profile", "segments"]
    type_in(page, [*segments, 0, "move"], "0.2 m")
    type_in(page, [*segments, 1, "dwell"], "0.2 s")
    type_in(page, [*segments, 2, "move"], "-0.1 m")
    accepted(page)
    # 0.2 m at 0.5 m/s and 5 m/s^2 (0.5 s), still 0.2 s, back 0.1 m (0.3 s): the service's profile ends at 1 s
    end = float(page.get_attribute("#profile-plot-0", "data-end"))
    assert end == pytest.approx(0.2 / 0.5 + 0.5 / 5 + 0.2 + 0.1 / 0.5 + 0.5 / 5, rel=1e-9)
    last = page.evaluate("document.querySelector('#profile-plot-0').data[0].y.slice(-1)[0]")
    assert last == pytest.approx(100.0)  # mm from home
    # a problem of one segment is shown at that segment's field
    type_in(page, [*segments, 2, "velocity"], "-1 m/s")
    wait_until(page, "document.querySelector('.field.bad') !== null", timeout_s=WAIT_S)
    bad = page.query_selector_all(".field.bad input")
    assert [b.get_attribute("data-path") for b in bad] == [
        json.dumps([*segments, 2, "velocity"], separators=(",", ":"))
    ]
    type_in(page, [*segments, 2, "velocity"], "0.5 m/s")
    accepted(page)

    # drag mount_0 (front-left, at x 0.1, y 0.1 m) 0.2 m to the right on the plan view: the mounts are listed
    at = page.evaluate(
        """(() => { const n = document.querySelector('#plan'); const L = n._fullLayout; const s = L.shapes[0];
        const box = n.querySelector('.main-svg').getBoundingClientRect();
        const px = (x) => box.left + L._size.l + L.xaxis.l2p(x);
        const py = (y) => box.top + L._size.t + L.yaxis.l2p(y);
        return {x: px((s.x0 + s.x1) / 2), y: py((s.y0 + s.y1) / 2), to: px((s.x0 + s.x1) / 2 + 0.2)}; })()"""
    )
    page.mouse.move(at["x"], at["y"])
    page.mouse.down()
    for k in range(1, 11):
        page.mouse.move(at["x"] + (at["to"] - at["x"]) * k / 10, at["y"])
    page.mouse.up()
    accepted(page)
    first = page.evaluate("document.querySelector('#mount-table tbody tr').cells[2].textContent")
    x, y, _ = (float(v) for v in first.split(","))
    assert x == pytest.approx(0.3, abs=0.02) and y == pytest.approx(0.1, abs=0.01)
    assert page.query_selector(field(["isolators", "list", 0, "position", 0])) is not None
    # the layout helper lays four out around the c.g. again
    page.click("#layout-mounts")
    accepted(page)
    assert page.query_selector(field(["isolators", "layout", "span_x"])) is not None
    assert not page.errors, page.errors


def test_an_answer_to_an_older_check_never_marks_newer_typing_accepted(page, base_url: str) -> None:
    """A check's answer that lands after the engineer typed again is for the scene as it was: the page keeps
    saying it is checking, and shows the newer scene's mass once its own answer lands."""
    page.goto(f"{base_url}/ui/scene?example=article-scriber")
    wait_until(page, "document.querySelector('#base-mass') !== null", timeout_s=WAIT_S)
    accepted(page)
    assert page.inner_text("#base-mass") == "10.02 t"
    held = []  # the checks asked from here on, answered when the test says
    page.route("**/scenes/check", lambda route: held.append(route))
    type_in(page, ["machine", "block", "density"], "1350 kg/m^3")  # half the granite's
    page.wait_for_timeout(800)  # past the check's delay: the half-density check is asked and held
    assert len(held) == 1
    type_in(page, ["machine", "block", "density"], "2025 kg/m^3")  # typed while that answer is on its way
    held.pop().continue_()  # the older answer lands now
    page.wait_for_timeout(100)
    assert page.inner_text("#check-status") == "Checking…"
    assert page.is_disabled("#run")
    assert page.inner_text("#base-mass") == "10.02 t"  # not the held answer's 5.01 t
    page.unroute("**/scenes/check")  # the newer check goes through
    for route in held:
        route.continue_()
    accepted(page)
    assert page.inner_text("#base-mass") == "7.518 t"  # 2.6 x 4.2 x 0.34 m at 2025 kg/m^3
