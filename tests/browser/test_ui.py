"""The web page in a real headless Chromium (Debian's, driven by Playwright) against a real
``isolab serve``: submit the isolator-comparison example from /ui/new, watch it reach done, change the sweep
plot's axes, open a case, compare isolator types; the plots must draw, the console stay clean and every
request stay on the service (no CDN). One service runs with ISOLAB_API_TOKEN set.

``make browser`` installs Chromium where it is missing; without it these tests are skipped."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from ui_driver import (
    CHROMIUM,
    ConsoleErrors,
    overlapping,
    plot_rendered,
    service,
    settle,
    submit_example,
    wait_done,
    wait_until,
)

from tests.shared_cluster import shared_scheduler

pytestmark = [
    pytest.mark.slow,  # services, clusters or processes of their own: `make test-fast` skips them
    pytest.mark.skipif(
        not CHROMIUM.exists(), reason=f"no {CHROMIUM}: `make browser` installs Debian's chromium"
    ),
]

TOKEN = "s3cret-token-of-the-shop-floor"
VIEWPORT = {"width": 1300, "height": 900}
YTITLES = "#traces text[class^='y'][class$='title']"
"""The y-axis titles of a figure of several panels (plotly's ``ytitle``, ``y2title``...)."""
LEGENDS = "#traces g.infolayer > g[class^='legend']"
"""The legends of a figure (plotly's ``legend``, ``legend2``...)."""
MOTIONS = re.compile(r"^(heave|pitch|roll|yaw|surge|sway)( \+ (heave|pitch|roll|yaw|surge|sway))?$")


@pytest.fixture(scope="module")
def open_service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with service(tmp_path_factory.mktemp("ui"), scheduler=shared_scheduler(2)) as svc:
        yield svc.url


@pytest.fixture
def page(chromium, open_service: str) -> Iterator:
    """A fresh tab whose requests are recorded (``page.requested``) and console errors gathered
    (``page.errors``)."""
    context = chromium.new_context(viewport=VIEWPORT)
    tab = context.new_page()
    tab.errors = ConsoleErrors(tab)
    tab.requested = []
    tab.on("request", lambda r: tab.requested.append(r.url))
    yield tab
    context.close()


def only_local(page, base: str) -> None:
    foreign = [u for u in page.requested if not (u.startswith(base) or u.startswith(("blob:", "data:")))]
    assert not foreign, f"requests that left the service: {foreign[:5]}"


def test_submit_watch_sweep_and_case(page, open_service: str) -> None:
    base = open_service
    study_id = submit_example(page, base)
    assert re.fullmatch(r"[0-9a-f]{32}", study_id)
    wait_done(page)
    assert page.inner_text("#status").count("12 / 12") == 1
    # the definition in the units the author wrote
    params = page.inner_text("#parameters")
    assert "0.5 g" in params and "2 g" in params and "active, air, elastomer" in params
    # the error estimate and the model, drawn once
    page.wait_for_selector("#error-estimate")
    assert "rk4" in page.inner_text("#model")
    settle(1.0)
    assert page.locator("#model table").count() == 1 and page.locator("#model dl").count() == 1
    # the sweep plot: drawn, then redrawn on other axes, labelled in words and units
    assert plot_rendered(page, "#sweep")
    assert "stage y acceleration [g]" in page.text_content("#sweep .xtitle")
    page.select_option("#x", "isolator_type")
    page.select_option("#y", "peak_rotation_rx")
    page.select_option("#colour", "")
    wait_until(page, "document.querySelector('#sweep .ytitle').textContent.includes('rotation')")
    assert "isolator type" in page.text_content("#sweep .xtitle")
    assert page.text_content("#sweep .ytitle") == "peak absolute rotation of the machine base, rx [mrad]"
    assert plot_rendered(page, "#sweep")
    # the case table and its filter language
    assert page.locator("#case-table tbody tr").count() == 12
    page.fill("#filter", "isolator_type==air,peak_displacement_y<50 mm")
    page.fill("#sort", "-stage_y_acceleration")
    page.click("#query button[type=submit]")
    wait_until(page, "document.querySelectorAll('#case-table tbody tr').length === 4")
    assert "4 of 12 cases match" in page.inner_text("#matched")
    with page.expect_download() as csv:  # the filtered table, fetched with the page's credentials
        page.click("#csv")
    lines = Path(csv.value.path()).read_text().splitlines()
    assert lines[0].startswith("case,") and len(lines) == 5
    with page.expect_download() as netcdf:
        page.click("#netcdf")
    assert Path(netcdf.value.path()).read_bytes()[:4] == b"\x89HDF"
    assert page.errors == []
    page.fill("#filter", "no_such_column<1")
    page.click("#query button[type=submit]")
    page.wait_for_selector("#query-error .error")
    assert "no_such_column" in page.inner_text("#query-error")
    assert len(page.errors) == 1 and "status of 422" in page.errors[0]  # Chromium logs the refused query
    page.errors.clear()
    # a case: traces, stage profiles, modes, settling
    page.goto(f"{base}/ui/studies/{study_id}/cases/7")
    page.wait_for_selector("#traces svg.main-svg", timeout=60_000)
    assert plot_rendered(page, "#traces")
    titles = page.text_content("#traces")
    assert "dynamic" in titles and "preload" in titles and "settled" in titles
    # axes in words and the study's units: its accelerations were written in g
    ytitles = [t.strip() for t in page.locator(YTITLES).all_text_contents()]
    assert "stage accelerationalong its axis [g]" in ytitles, ytitles  # the <br> joins the two lines
    assert any(t.endswith("c.g. [mm]") for t in ytitles) and any(t.endswith("[mrad]") for t in ytitles)
    # one legend per panel, the isolators named by where they stand
    panels = page.locator(YTITLES).count()
    assert panels == 7 and page.locator(LEGENDS).count() == panels
    legends = page.locator(LEGENDS).all_text_contents()
    assert max(page.locator(LEGENDS).nth(k).locator("g.traces").count() for k in range(7)) == 12
    assert any("front-left z" in t and "back-right x" in t for t in legends), legends
    assert overlapping(page, LEGENDS) == []  # the mounts' 12 entries stay beside their own panel
    assert "front-left (x 0.20 m, y 0.30 m)" in page.inner_text("#isolators")
    with page.expect_download() as traces_csv:  # every sample, in the units shown
        page.click("#traces-csv")
    rows = Path(traces_csv.value.path()).read_text().splitlines()
    assert rows[0].startswith("time [s],") and "stage acceleration along its axis: stage y [g]" in rows[0]
    column = rows[0].split(",").index("stage acceleration along its axis: stage y [g]")
    written = re.search(r"stage_y_acceleration\s+([0-9.]+) g", page.inner_text("#facts"))
    assert written, page.inner_text("#facts")
    peak = max(abs(float(r.split(",")[column])) for r in rows[1:])
    assert peak == pytest.approx(float(written.group(1)), rel=1e-6)  # the case's own, in g
    names = [page.inner_text(f"#mode-table tbody tr:nth-child({k}) td:nth-child(2)") for k in range(1, 7)]
    assert all(MOTIONS.match(n) for n in names), names
    assert "heave" in " ".join(names)
    assert "after the last move" in page.inner_text("#settling")
    # the catalog lists it, done
    page.goto(f"{base}/ui/")
    page.wait_for_selector(f"#study-table tr[data-id='{study_id}'] .status-done")
    page.fill("#search", "no such study")
    assert page.locator("#study-table").count() == 0
    assert page.errors == []
    only_local(page, base)


def test_new_study_places_the_services_objections_at_their_lines(page, open_service: str) -> None:
    base = open_service
    page.goto(f"{base}/ui/new")
    page.wait_for_selector("#source option[value='example:isolator-comparison']", state="attached")
    page.select_option("#source", "example:isolator-comparison")
    page.wait_for_selector("#check.ok")
    assert "12 cases" in page.inner_text("#check")
    text = page.input_value("#text")
    lines = text.split("\n")
    bad = next(i for i, line in enumerate(lines) if "num: 4" in line) + 1
    page.fill("#text", text.replace("num: 4", "num: 0"))
    page.wait_for_selector("#check.error")
    assert page.inner_text("#problems li .line") == f"line {bad}"
    assert page.inner_text("#gutter .bad").endswith(str(bad))
    assert "greater than or equal to 1" in page.inner_text("#backdrop .note")
    assert page.is_disabled("#submit")
    # the 422 of the check is the only console error (Chromium logs every refused request)
    assert all("422" in e for e in page.errors), page.errors
    only_local(page, base)


def test_comparison_and_reference_pages(page, open_service: str) -> None:
    base = open_service
    page.goto(f"{base}/ui/compare")
    page.wait_for_selector("#source option", state="attached")
    page.click("#run")
    page.wait_for_selector("#comparison-table", timeout=60_000)
    assert plot_rendered(page, "#bars")
    header = page.inner_text("#comparison-table thead")
    assert all(t in header for t in ("active", "air", "elastomer"))
    assert page.locator("#comparison-table td.best").count() > 5
    page.goto(f"{base}/docs")
    page.wait_for_selector(".swagger-ui .info", timeout=30_000)
    page.click("#isolab-back a")  # the reference leads back to the page
    page.wait_for_url(f"{base}/ui/", timeout=30_000)
    page.goto(f"{base}/redoc")
    page.wait_for_selector("redoc .api-info, .redoc-wrap", timeout=30_000)
    assert page.errors == []
    only_local(page, base)


def test_the_example_with_yaml_aliases_checks_and_compares(page, open_service: str) -> None:
    """scriber-criteria.yaml repeats its floor spectrum per axis by a YAML alias: /ui/new checks it and
    /ui/compare runs it, as the command line does."""
    base = open_service
    page.goto(f"{base}/ui/new?from=example:scriber-criteria")
    page.wait_for_selector("#check.ok", timeout=30_000)
    assert "scriber-criteria: 3 cases" in page.inner_text("#check")
    assert "*site" in page.input_value("#text") and not page.is_disabled("#submit")
    page.goto(f"{base}/ui/compare")
    page.wait_for_selector("#source option[value='example:scriber-criteria']", state="attached")
    page.select_option("#source", "example:scriber-criteria")
    page.click("#run")
    page.wait_for_selector("#comparison-table", timeout=60_000)
    assert "margin" in page.inner_text("#comparison-table")
    assert page.errors == []
    only_local(page, base)


def test_with_a_token_the_page_asks_once_and_the_api_stays_guarded(chromium, tmp_path: Path) -> None:
    with service(tmp_path, token=TOKEN, scheduler=shared_scheduler(1)) as svc:
        base = svc.url
        assert httpx.get(f"{base}/studies").status_code == 401
        assert httpx.get(f"{base}/ui/").status_code == 200  # the shell holds no data
        context = chromium.new_context(viewport=VIEWPORT)
        page = context.new_page()
        errors = ConsoleErrors(page, ignore=("status of 401",))
        page.goto(f"{base}/ui/")
        page.wait_for_selector("#token-dialog", timeout=30_000)
        page.fill("#token-input", TOKEN)
        page.click("#token-ok")
        page.wait_for_selector("#studies p.muted:has-text('No study yet')")
        assert page.evaluate("sessionStorage.getItem('isolab-token')") == TOKEN
        # the next page of the tab asks no more, and its guarded requests go through
        page.goto(f"{base}/ui/new")
        page.wait_for_selector("#source option[value='example:isolator-comparison']", state="attached")
        page.select_option("#source", "example:isolator-comparison")
        page.wait_for_selector("#check.ok")
        assert page.locator("#token-dialog").count() == 0
        assert errors == []
        context.close()


CRAFTED = '"><img src=x onerror="window.stolen=sessionStorage.getItem(`isolab-token`)">'


def test_a_crafted_path_in_the_services_messages_runs_no_script(page, open_service: str) -> None:
    base = open_service
    page.goto(f"{base}/ui/new")
    page.evaluate("sessionStorage.setItem('isolab-token', 'secret-of-the-tab')")
    page.wait_for_selector("#source option[value='example:isolator-comparison']", state="attached")
    page.select_option("#source", "example:isolator-comparison")
    page.wait_for_selector("#check.ok")
    text = page.input_value("#text")
    crafted = text.replace("path: isolators.preset", f"path: '{CRAFTED}'", 1)
    assert crafted != text
    page.fill("#text", crafted)
    page.wait_for_selector("#check.error")
    assert CRAFTED in page.inner_text("#problems")  # shown as text...
    page.hover("#gutter .bad")
    page.hover("#problems li")
    page.wait_for_timeout(500)
    # ...never as markup: no element made from it, no handler run, the token unread
    assert page.locator("#gutter img, #backdrop img, #problems img, #check img").count() == 0
    assert page.evaluate("window.stolen === undefined")
    title = page.get_attribute("#gutter .bad", "title")
    assert CRAFTED in title
    # and a page's own inline script would not run either: the policy allows the service's files alone
    page.evaluate(
        "() => { const s = document.createElement('img'); s.src = 'x';"
        " s.setAttribute('onerror', 'window.stolen = 1'); document.body.appendChild(s); }"
    )
    page.wait_for_timeout(500)
    assert page.evaluate("window.stolen === undefined")


def test_pages_carry_the_security_headers(open_service: str) -> None:
    for path in ("/ui/", "/ui/new", "/ui/compare", "/docs"):
        r = httpx.get(f"{open_service}{path}")
        assert "script-src 'self'" in r.headers["content-security-policy"], path
        assert r.headers["x-content-type-options"] == "nosniff"
        assert r.headers["referrer-policy"] == "no-referrer"
