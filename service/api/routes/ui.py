"""The web page (``/ui/...``) and the API reference pages (``/docs``, ``/redoc``), every asset served by
the service itself: no CDN, so they work on a network without the internet.

The page is static HTML and vanilla JavaScript (``service/ui/``); its data comes only from the REST API,
with the bearer token when the service has one (the page asks for it once and keeps it in the tab's
sessionStorage). The page shells and their assets carry no data and are served without a token, as the
API description is. The plotting library is the ``plotly.min.js`` that the PyPI ``plotly`` package ships;
Swagger UI and ReDoc are the copies the PyPI ``fastapi-offline`` package ships.

Every answer of the app carries ``X-Content-Type-Options: nosniff`` and ``Referrer-Policy: no-referrer``,
and every HTML page a Content-Security-Policy (:data:`PAGE_POLICY`) that runs the service's own script files
alone: no inline script, no handler attribute, no ``eval``, nothing from another host
(:class:`PageHeaders`). Swagger UI's one inline set-up script is allowed by its hash, nothing else.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import importlib.util
import re
from pathlib import Path

from fastapi import APIRouter, FastAPI, HTTPException
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

UI_DIR = Path(__file__).resolve().parents[2] / "ui"
"""The page's HTML, JavaScript and CSS (package data of isolab.service)."""
ASSETS = "/ui/assets"
DOCS_ASSETS = "/ui/vendor/docs"
PLOTLY_JS = "/ui/vendor/plotly.min.js"
REDOC_JS = "/ui/vendor/redoc.standalone.js"
REDOC_LOGO_URL = "https://cdn.redoc.ly/redoc/logo-mini.svg"
"""The one address ReDoc's bundle reaches for by itself (the sidebar's logo): pointed at a local image."""

PAGE_POLICY_PARTS: dict[str, str] = {
    "default-src": "'self'",
    "script-src": "'self'",
    "style-src": "'self' 'unsafe-inline'",  # plotly and ReDoc set styles as they draw
    "img-src": "'self' data: blob:",
    "connect-src": "'self'",
    "worker-src": "'self' blob:",  # ReDoc's search runs in a worker made from a blob
    "object-src": "'none'",
    "base-uri": "'none'",
    "form-action": "'self'",
    "frame-ancestors": "'none'",
}
"""The Content-Security-Policy of every HTML page, by directive."""
PAGE_POLICY = "; ".join(f"{name} {value}" for name, value in PAGE_POLICY_PARTS.items())
ALWAYS = {"x-content-type-options": "nosniff", "referrer-policy": "no-referrer"}
"""Headers of every answer of the app."""
_INLINE_SCRIPT = re.compile(r"<script>(.*?)</script>", re.DOTALL)

router = APIRouter(include_in_schema=False)


def policy_allowing_inline(html: str) -> str:
    """:data:`PAGE_POLICY` with the inline scripts of ``html`` (its own, fixed set-up code) allowed by
    their SHA-256 hashes."""
    hashes = [
        "'sha256-" + base64.b64encode(hashlib.sha256(code.encode()).digest()).decode() + "'"
        for code in _INLINE_SCRIPT.findall(html)
    ]
    parts = {**PAGE_POLICY_PARTS, "script-src": " ".join([PAGE_POLICY_PARTS["script-src"], *hashes])}
    return "; ".join(f"{name} {value}" for name, value in parts.items())


class PageHeaders:
    """ASGI middleware: :data:`ALWAYS` on every answer, and :data:`PAGE_POLICY` on an HTML answer that
    does not set a policy of its own."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                for name, value in ALWAYS.items():
                    headers.setdefault(name, value)
                if headers.get("content-type", "").startswith("text/html"):
                    headers.setdefault("content-security-policy", PAGE_POLICY)
            await send(message)

        await self.app(scope, receive, send_with_headers)


def package_dir(name: str) -> Path:
    """The folder of an installed package, found without importing it."""
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError(f"the package {name!r} is not installed (pip install -e .)")
    return Path(next(iter(spec.submodule_search_locations)))


def _page(name: str) -> FileResponse:
    return FileResponse(UI_DIR / name, media_type="text/html; charset=utf-8", headers=NO_STORE)


NO_STORE = {"Cache-Control": "no-cache"}


@router.get("/")
def root() -> RedirectResponse:
    return RedirectResponse("/ui/", status_code=307)


@router.get("/ui")
def ui_root() -> RedirectResponse:
    return RedirectResponse("/ui/", status_code=307)


@router.get("/ui/")
def studies_page() -> FileResponse:
    """The studies in the catalog."""
    return _page("index.html")


@router.get("/ui/new")
def new_page() -> FileResponse:
    """Write a study (from an example or a stored one), check it and submit it."""
    return _page("new.html")


@router.get("/ui/scene")
def scene_page() -> FileResponse:
    """Build or change a scene: forms with units, the machine in 3D, its modes, a run at once."""
    return _page("scene.html")


@router.get("/ui/compare")
def compare_page() -> FileResponse:
    """Isolator types side by side on one scene."""
    return _page("compare.html")


@router.get("/ui/calibrate")
def calibrate_page() -> FileResponse:
    """Start a calibration: a scene, a measurement (CSV) and the parameters to fit."""
    return _page("calibration.html")


@router.get("/ui/calibrations/{calibration_id}")
def calibration_page(calibration_id: str) -> FileResponse:
    """One calibration: progress, goodness of fit, fitted values, measured against fitted traces."""
    return _page("calibration.html")


@router.get("/ui/studies/{study_id}")
def study_page(study_id: str) -> FileResponse:
    """One study: definition, progress, sweep plot, case table, downloads."""
    return _page("study.html")


@router.get("/ui/studies/{study_id}/cases/{case}")
def case_page(study_id: str, case: int) -> FileResponse:
    """One case: time histories, stage profiles, modes, settling."""
    return _page("case.html")


@router.get(PLOTLY_JS)
def plotly_js() -> FileResponse:
    """plotly.js as the PyPI ``plotly`` package ships it."""
    path = package_dir("plotly") / "package_data" / "plotly.min.js"
    if not path.is_file():
        raise HTTPException(status_code=404, detail="the installed plotly package ships no plotly.min.js")
    return FileResponse(path, media_type="text/javascript; charset=utf-8")


@functools.lru_cache(maxsize=1)
def _redoc_bundle() -> bytes:
    path = package_dir("fastapi_offline") / "static" / "redoc.standalone.js"
    return path.read_bytes().replace(REDOC_LOGO_URL.encode(), f"{DOCS_ASSETS}/favicon.png".encode())


@router.get(REDOC_JS)
def redoc_js() -> Response:
    """ReDoc as fastapi-offline ships it, its sidebar logo taken from this service instead of a CDN."""
    return Response(_redoc_bundle(), media_type="text/javascript; charset=utf-8")


BACK_TO_PAGE = (
    '<nav id="isolab-back" style="font: 14px system-ui, sans-serif; padding: 0.5em 1em; background: #1d2b3a">'
    '<a href="/ui/" style="color: #fff; text-decoration: none">&larr; isolab: back to the studies</a></nav>'
)
"""The bar atop the API reference pages that leads back to the web page (markup only, no script)."""


def with_link_back(page: HTMLResponse) -> HTMLResponse:
    """``page`` with :data:`BACK_TO_PAGE` first in its body (its headers, the policy among them, kept)."""
    html = bytes(page.body).decode().replace("<body>", "<body>\n" + BACK_TO_PAGE, 1)
    headers = {k: v for k, v in page.headers.items() if k.lower() != "content-length"}
    return HTMLResponse(html, headers=headers)


@router.get("/docs")
def swagger_ui() -> HTMLResponse:
    page = get_swagger_ui_html(
        openapi_url="/openapi.json",
        title="isolab - API reference",
        swagger_js_url=f"{DOCS_ASSETS}/swagger-ui-bundle.js",
        swagger_css_url=f"{DOCS_ASSETS}/swagger-ui.css",
        swagger_favicon_url=f"{DOCS_ASSETS}/favicon.png",
    )
    page.headers["Content-Security-Policy"] = policy_allowing_inline(bytes(page.body).decode())
    return with_link_back(page)


@router.get("/redoc")
def redoc() -> HTMLResponse:
    return with_link_back(
        get_redoc_html(
            openapi_url="/openapi.json",
            title="isolab - API reference",
            redoc_js_url=REDOC_JS,
            redoc_favicon_url=f"{DOCS_ASSETS}/favicon.png",
            with_google_fonts=False,
        )
    )


def add_ui(app: FastAPI) -> None:
    """Serve the page, its assets and the API reference pages from ``app`` (create it with
    ``docs_url=None, redoc_url=None``: these routes replace FastAPI's CDN-backed ones)."""
    app.include_router(router)
    app.add_middleware(PageHeaders)
    app.mount(ASSETS, StaticFiles(directory=UI_DIR / "assets"), name="ui-assets")
    app.mount(
        DOCS_ASSETS, StaticFiles(directory=package_dir("fastapi_offline") / "static"), name="docs-assets"
    )
