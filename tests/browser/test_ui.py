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
    browser,
    plot_rendered,
    service,
    submit_example,
    wait_done,
    wait_until,
)

pytestmark = [
    pytest.mark.slow,  # services, clusters or processes of their own: `make test-fast` skips them
    pytest.mark.skipif(
        not CHROMIUM.exists(), reason=f"no {CHROMIUM}: `make browser` installs Debian's chromium"
    ),
]

TOKEN = "s3cret-token-of-the-shop-floor"
VIEWPORT = {"width": 1300, "height": 900}
MOTIONS = re.compile(r"^(heave|pitch|roll|yaw|surge|sway)( \+ (heave|pitch|roll|yaw|surge|sway))?$")


@pytest.fixture(scope="module")
def chromium() -> Iterator:
    with browser() as b:
        yield b


@pytest.fixture(scope="module")
def open_service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with service(tmp_path_factory.mktemp("ui")) as svc:
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
    # the error estimate and the model
    page.wait_for_selector("#error-estimate")
    assert "rk4" in page.inner_text("#model")
    # the sweep plot: drawn, then redrawn on other axes
    assert plot_rendered(page, "#sweep")
    assert "stage_y_acceleration [g]" in page.text_content("#sweep .xtitle")
    page.select_option("#x", "isolator_type")
    page.select_option("#y", "peak_rotation_rx")
    page.select_option("#colour", "")
    wait_until(page, "document.querySelector('#sweep .ytitle').textContent.includes('peak_rotation_rx')")
    assert "isolator_type" in page.text_content("#sweep .xtitle")
    assert "[mrad]" in page.text_content("#sweep .ytitle")
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
    assert "dynamic" in titles and "preload" in titles and "stage accel" in titles and "settled" in titles
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
    page.goto(f"{base}/redoc")
    page.wait_for_selector("redoc .api-info, .redoc-wrap", timeout=30_000)
    assert page.errors == []
    only_local(page, base)


def test_with_a_token_the_page_asks_once_and_the_api_stays_guarded(chromium, tmp_path: Path) -> None:
    with service(tmp_path, token=TOKEN, workers=1) as svc:
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
