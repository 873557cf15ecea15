"""The web page (``/ui/...``) and the API reference pages (``/docs``, ``/redoc``), every asset served by
the service itself: no CDN, so they work on a network without the internet.

The page is static HTML and vanilla JavaScript (``service/ui/``); its data comes only from the REST API,
with the bearer token when the service has one (the page asks for it once and keeps it in the tab's
sessionStorage). The page shells and their assets carry no data and are served without a token, as the
API description is. The plotting library is the ``plotly.min.js`` that the PyPI ``plotly`` package ships;
Swagger UI and ReDoc are the copies the PyPI ``fastapi-offline`` package ships.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

from fastapi import APIRouter, FastAPI, HTTPException
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles

UI_DIR = Path(__file__).resolve().parents[2] / "ui"
"""The page's HTML, JavaScript and CSS (package data of isolab.service)."""
ASSETS = "/ui/assets"
DOCS_ASSETS = "/ui/vendor/docs"
PLOTLY_JS = "/ui/vendor/plotly.min.js"
REDOC_JS = "/ui/vendor/redoc.standalone.js"
REDOC_LOGO_URL = "https://cdn.redoc.ly/redoc/logo-mini.svg"
"""The one address ReDoc's bundle reaches for by itself (the sidebar's logo): pointed at a local image."""

router = APIRouter(include_in_schema=False)


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


@router.get("/ui/compare")
def compare_page() -> FileResponse:
    """Isolator types side by side on one scene."""
    return _page("compare.html")


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


@router.get("/docs")
def swagger_ui() -> HTMLResponse:
    return get_swagger_ui_html(
        openapi_url="/openapi.json",
        title="isolab - API reference",
        swagger_js_url=f"{DOCS_ASSETS}/swagger-ui-bundle.js",
        swagger_css_url=f"{DOCS_ASSETS}/swagger-ui.css",
        swagger_favicon_url=f"{DOCS_ASSETS}/favicon.png",
    )


@router.get("/redoc")
def redoc() -> HTMLResponse:
    return get_redoc_html(
        openapi_url="/openapi.json",
        title="isolab - API reference",
        redoc_js_url=REDOC_JS,
        redoc_favicon_url=f"{DOCS_ASSETS}/favicon.png",
        with_google_fonts=False,
    )


def add_ui(app: FastAPI) -> None:
    """Serve the page, its assets and the API reference pages from ``app`` (create it with
    ``docs_url=None, redoc_url=None``: these routes replace FastAPI's CDN-backed ones)."""
    app.include_router(router)
    app.mount(ASSETS, StaticFiles(directory=UI_DIR / "assets"), name="ui-assets")
    app.mount(
        DOCS_ASSETS, StaticFiles(directory=package_dir("fastapi_offline") / "static"), name="docs-assets"
    )
