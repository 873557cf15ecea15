"""Driving the web page in a real headless Chromium: Debian's ``/usr/bin/chromium`` under Playwright for
Python (``playwright install`` is never run: it downloads browsers, which this network does not allow).

Shared by the browser tests and ``python -m tests.browser.screenshots``: start a real ``isolab serve``
(:class:`benchmarks.live_service.ServiceProcess`), open pages, walk the flows a person would.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from benchmarks.live_service import ServiceProcess

CHROMIUM = Path("/usr/bin/chromium")
"""Debian's chromium package (``make browser`` installs it)."""
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
"""Without the background-networking flags Chromium keeps trying to reach Google's hosts, which this
machine's closed network refuses."""
EXAMPLE = "isolator-comparison"
STUDY_TIMEOUT_S = 120.0
"""Longest wait for a study. The engine's kernels are compiled (fresh checkout) or loaded by the service's
warm-up before a page is opened (:func:`service` waits for it, up to ``KERNELS_TIMEOUT_S``), so a study
runs in seconds."""
KERNELS_TIMEOUT_S = 480.0
"""Longest wait for the service's warm-up: on an empty kernel cache it compiles each pair once (the rk4
kernels about 100 s on the 2-core machine)."""


@contextmanager
def browser() -> Iterator:
    """A headless Chromium (the system one), closed afterwards."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_FLAGS, headless=True)
        try:
            yield b
        finally:
            b.close()


@contextmanager
def service(
    tmp: Path, token: str | None = None, workers: int = 2, scheduler: str | None = None
) -> Iterator[ServiceProcess]:
    """A real ``isolab serve`` on a free loopback port, with a study store under ``tmp``: with a cluster
    of ``workers`` of its own, or joined to the Dask ``scheduler`` at that address (the tests give the
    shared cluster of their process, tests/shared_cluster.py)."""
    env = {"ISOLAB_API_TOKEN": token} if token else {"ISOLAB_API_TOKEN": ""}
    env["ISOLAB_KERNEL_WARMUP"] = "on"  # the suite turns it off (tests/conftest.py); a page waits for it
    if scheduler is not None:
        env["DASK_SCHEDULER_ADDRESS"] = scheduler
    with ServiceProcess(tmp / "data", workers=workers, env=env) as svc:
        wait_kernels(svc, token)
        yield svc


def wait_kernels(svc: ServiceProcess, token: str | None = None, timeout: float = KERNELS_TIMEOUT_S) -> None:
    """Wait until ``/health`` says the workers hold the engine's kernels (ready, or failed: then each
    study compiles its own)."""
    import httpx

    headers = {"Authorization": f"Bearer {token}"} if token else {}
    deadline = time.monotonic() + timeout
    while True:
        kernels = httpx.get(svc.url + "/health", headers=headers, timeout=10.0).json().get("kernels") or {}
        if kernels.get("state") in ("ready", "failed", "off"):
            return
        assert time.monotonic() < deadline, f"the service's kernels still {kernels} after {timeout} s"
        time.sleep(0.2)


class ConsoleErrors(list):
    """Console errors and uncaught exceptions of a page, gathered as they happen."""

    def __init__(self, page, ignore: tuple[str, ...] = ()):
        super().__init__()
        self.ignore = ignore
        page.on("console", lambda m: m.type == "error" and self._add(f"console: {m.text}"))
        page.on("pageerror", lambda e: self._add(f"uncaught: {e}"))

    def _add(self, text: str) -> None:
        if not any(s in text for s in self.ignore):
            self.append(text)


def plot_rendered(page, selector: str) -> bool:
    """The Plotly figure in ``selector`` has drawn something: an SVG with traces (paths or points)."""
    return page.eval_on_selector(
        selector,
        """node => {
            const svg = node.querySelector('svg.main-svg');
            if (!svg) return false;
            const box = svg.getBoundingClientRect();
            const marks = node.querySelectorAll(
                '.scatterlayer .trace path, .scatterlayer .point, .barlayer .point');
            return box.width > 0 && box.height > 0 && marks.length > 0;
        }""",
    )


def overlapping(page, selector: str) -> list[tuple[str, str]]:
    """The pairs of the elements matching ``selector`` whose boxes on the page overlap (by more than a
    pixel each way), each element named by its text: labels drawn over one another."""
    return [
        tuple(pair)
        for pair in page.eval_on_selector_all(
            selector,
            """nodes => {
                const boxes = nodes.map((n) => [n.textContent.trim(), n.getBoundingClientRect()]);
                const out = [];
                boxes.forEach(([a, p], i) => boxes.slice(i + 1).forEach(([b, q]) => {
                    const w = Math.min(p.right, q.right) - Math.max(p.left, q.left);
                    const h = Math.min(p.bottom, q.bottom) - Math.max(p.top, q.top);
                    if (w > 1 && h > 1) out.push([a, b]);
                }));
                return out;
            }""",
        )
    ]


def submit_example(page, base: str, example: str = EXAMPLE) -> str:
    """From /ui/new: load the example, wait for the service's check, submit; the new study's id."""
    page.goto(f"{base}/ui/new")
    page.wait_for_selector(f"#source option[value='example:{example}']", state="attached")
    page.select_option("#source", f"example:{example}")
    page.wait_for_selector("#check.ok", timeout=30_000)
    page.click("#submit")
    page.wait_for_url(f"{base}/ui/studies/*", timeout=30_000)
    return page.url.rstrip("/").split("/")[-1]


def wait_done(page, timeout_s: float = STUDY_TIMEOUT_S) -> None:
    """On a study's page: wait until its badge says done and the sweep plot is drawn."""
    page.wait_for_selector("#title .status-done", timeout=timeout_s * 1000)
    wait_until(page, "document.querySelector('#sweep svg.main-svg') !== null", timeout_s=30)


def wait_until(page, expression: str, timeout_s: float = 30.0) -> None:
    """Poll a JavaScript expression until it is true. The pages' Content-Security-Policy forbids eval,
    which Playwright's ``wait_for_function`` uses for a predicate given as text; ``page.evaluate`` runs
    the expression through the browser's debugging protocol, outside the page's policy."""
    deadline = time.monotonic() + timeout_s
    while not page.evaluate(expression):
        if time.monotonic() > deadline:
            raise TimeoutError(f"{expression} still false after {timeout_s} s")
        time.sleep(0.1)


def settle(seconds: float = 0.3) -> None:
    time.sleep(seconds)
