"""The shape of the code: one namespace, one direction of imports, no circles, thin routes.

The import graph is read from the source with :mod:`ast` (every ``import``, including those inside
functions), so a circle hidden in a function-level import is caught as well as a top-level one.
"""

from __future__ import annotations

import ast
import functools
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("engine", "studies", "service")
LAYER = {"engine": 0, "studies": 1, "service": 2}
"""A package may import only packages of a lower layer (and itself)."""
WEB = ("fastapi", "starlette", "uvicorn")


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["isolab", *parts])


def project_modules() -> dict[str, Path]:
    """``isolab.x.y`` -> source file, for every module of the three packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            out[_module_name(path)] = path
    return out


@functools.cache
def submodule(name: str) -> bool:
    """True when the dotted name is a module or package of the source tree."""
    parts = name.split(".")
    if parts[0] != "isolab" or len(parts) < 2:
        return False
    rel = ROOT.joinpath(*parts[1:])
    return rel.with_suffix(".py").is_file() or (rel / "__init__.py").is_file()


def imported_names(path: Path, module: str) -> list[str]:
    """Absolute names of every module ``path`` imports (anywhere in the file), relative imports resolved
    (each file read and parsed once per test process while it does not change: a dozen tests read the
    whole tree)."""
    stat = path.stat()
    return list(_imports_of(path, module, (stat.st_mtime_ns, stat.st_size)))


@functools.cache
def _imports_of(path: Path, module: str, stamp: tuple[int, int]) -> tuple[str, ...]:
    """:func:`imported_names` of ``path`` as it was at ``stamp`` (its modification time and size)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_pkg = path.name == "__init__.py"
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".")
                anchor = anchor if is_pkg else anchor[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base]) if base else ".".join(anchor)
            # ``from isolab.engine import model`` imports the submodule isolab.engine.model (the package's
            # __init__ runs first, but that is the package's own business, not an edge of this module)
            subs = [f"{base}.{a.name}" for a in node.names]
            names += subs if submodule(subs[0]) and all(submodule(s) for s in subs) else [base]
    return tuple(names)


def import_graph() -> dict[str, set[str]]:
    """Project module -> the project modules it imports."""
    mods = project_modules()
    graph = {}
    for name, path in mods.items():
        graph[name] = {n for n in imported_names(path, name) if n in mods and n != name}
    return graph


def _package(module: str) -> str:
    return module.split(".")[1]


def test_every_project_import_uses_the_isolab_namespace():
    bare = []
    for name, path in project_modules().items():
        for imp in imported_names(path, name):
            if imp.split(".")[0] in (*PACKAGES, "benchmarks"):
                bare.append(f"{path.relative_to(ROOT)} imports {imp}")
    for path in sorted((ROOT / "tests").rglob("*.py")):
        for imp in imported_names(path, "tests.x"):
            if imp.split(".")[0] in PACKAGES:
                bare.append(f"{path.relative_to(ROOT)} imports {imp}")
    assert not bare, "\n".join(bare)


def test_imports_go_one_way_service_studies_engine():
    wrong = [
        f"{a} imports {b}"
        for a, deps in import_graph().items()
        for b in deps
        if LAYER[_package(b)] > LAYER[_package(a)]
    ]
    assert not wrong, "\n".join(wrong)


def test_the_service_reaches_the_engine_only_through_studies():
    direct = [
        f"{a} imports {b}"
        for a, deps in import_graph().items()
        for b in deps
        if _package(a) == "service" and _package(b) == "engine"
    ]
    assert not direct, "\n".join(direct)


def test_the_import_graph_has_no_circle():
    graph = import_graph()
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                cycles.append([*stack[stack.index(dep) :], dep])
            elif dep not in state:
                visit(dep)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles)


def test_the_graph_reader_sees_a_circle_through_a_function_level_import(tmp_path):
    """The circle check is only as good as the reader: a function-level import must count."""
    a = tmp_path / "a.py"
    a.write_text("def f():\n    from isolab.studies.b import g\n    return g\n")
    assert "isolab.studies.b" in imported_names(a, "isolab.studies.a")
    rel = tmp_path / "c.py"
    rel.write_text("from .store import Store\n")
    assert "isolab.studies.store" in imported_names(rel, "isolab.studies.c")


def test_engine_and_studies_import_no_web_framework():
    web = [
        f"{name} imports {imp}"
        for name, path in project_modules().items()
        if _package(name) in ("engine", "studies")
        for imp in imported_names(path, name)
        if imp.split(".")[0] in WEB
    ]
    assert not web, "\n".join(web)


def test_the_engine_does_no_io_and_knows_no_schema_library():
    banned = ("xarray", "netCDF4", "pydantic", "yaml", "sqlite3", "httpx", "dask", "distributed")
    found = [
        f"{name} imports {imp}"
        for name, path in project_modules().items()
        if _package(name) == "engine"
        for imp in imported_names(path, name)
        if imp.split(".")[0] in banned
    ]
    assert not found, "\n".join(found)


def test_route_modules_are_thin():
    sizes = {
        p.name: len(p.read_text().splitlines()) for p in (ROOT / "service" / "api" / "routes").glob("*.py")
    }
    fat = {name: n for name, n in sizes.items() if n > 400}
    assert not fat, f"route modules over 400 lines: {fat}"


def test_no_module_is_named_for_a_technical_layer():
    vague = {"utils", "util", "helpers", "helper", "manager", "misc", "common"}
    found = [str(p.relative_to(ROOT)) for p in project_modules().values() if p.stem in vague]
    assert not found, found


@pytest.mark.slow
def test_a_wheel_installs_the_three_packages_under_one_namespace(tmp_path):
    """Build the wheel, install it (without dependencies) into a fresh virtual environment whose only other
    path is the development environment's site-packages for the dependencies, and import the packages from
    outside the source tree: the installed copies are used, the version comes from the metadata, and the
    wheel has no top-level ``engine``, ``studies`` or ``service``."""
    wheels = tmp_path / "wheels"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(wheels),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (wheel,) = wheels.glob("isolab-*.whl")
    tops = {n.split("/")[0] for n in zipfile.ZipFile(wheel).namelist()}
    assert "isolab" in tops and not tops & set(PACKAGES), tops
    members = zipfile.ZipFile(wheel).namelist()
    assert "isolab/studies/examples/article-scriber.yaml" in members
    assert "isolab/service/ui/study.html" in members and "isolab/service/ui/assets/common.js" in members
    init_dirs = {
        str(p.parent.relative_to(ROOT)) for pkg in PACKAGES for p in (ROOT / pkg).rglob("__init__.py")
    }
    shipped = {os.path.dirname(n).removeprefix("isolab/") for n in members if n.endswith("__init__.py")}
    assert init_dirs <= shipped, f"packages missing from the wheel: {init_dirs - shipped}"

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    site = subprocess.run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", site, str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    # dependencies from the development environment: a path line in a .pth file adds the directory, but its
    # own .pth files (the editable install's finder among them) are not run
    deps = next(p for p in sys.path if p.endswith("site-packages") and Path(p).is_dir())
    Path(site, "deps.pth").write_text(deps + "\n")
    code = (
        "import importlib.metadata, isolab.engine, isolab.studies, isolab.service, isolab.service.api.app;"
        "print(isolab.engine.__file__);"
        "print(isolab.engine.__version__ == importlib.metadata.version('isolab'))"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    out = subprocess.run(
        [str(py), "-c", code], cwd=tmp_path, env=env, check=True, capture_output=True, text=True, timeout=300
    ).stdout.split()
    assert out[0].startswith(site) and out[1] == "True", out


# ------------------------------------------------------------------------------------------------ rooms
STUDY_ROOMS = ("questions", "inputs", "results", "run", "answers", "authoring")
"""The rooms of ``isolab.studies``, lowest first: a room imports only its own modules, lower rooms and
the vocabulary directly in the package (``isolab.studies``, ``.units``, ``.quantities``); see
docs/architecture.md."""

SERVICE_ROOMS = {
    "settings": set(),
    "client": {"settings"},
    "plots": {"settings"},
    "api": {"settings", "plots"},
    "cli": {"settings", "client", "plots", "api"},
}
"""The rooms of ``isolab.service`` and the rooms each may import besides itself."""

MAX_LINES = 700
MAX_MODULES_PER_FOLDER = 10


def _room(module: str) -> str:
    """``isolab.studies.run.runner`` -> ``run``; a module directly in the package -> ``""``."""
    parts = module.split(".")
    return parts[2] if len(parts) > 3 else ""


def test_study_rooms_import_only_lower_rooms():
    rank = {"": -1, **{room: i for i, room in enumerate(STUDY_ROOMS)}}
    mods = project_modules()
    assert all(_room(m) in rank for m in mods if _package(m) == "studies"), "a studies room is not listed"
    wrong = [
        f"{a} ({_room(a) or 'vocabulary'}) imports {b} ({_room(b) or 'vocabulary'})"
        for a, deps in import_graph().items()
        if _package(a) == "studies"
        for b in deps
        if _package(b) == "studies" and rank[_room(b)] > rank[_room(a)]
    ]
    assert not wrong, "\n".join(wrong)


def test_service_rooms_import_only_their_allowed_rooms():
    wrong = []
    for a, deps in import_graph().items():
        if _package(a) != "service" or a == "isolab.service":
            continue
        room = a.split(".")[2]
        assert room in SERVICE_ROOMS, f"{a}: room {room!r} is not in SERVICE_ROOMS"
        for b in deps:
            if _package(b) == "service" and b != "isolab.service":
                other = b.split(".")[2]
                if other != room and other not in SERVICE_ROOMS[room]:
                    wrong.append(f"{a} ({room}) imports {b} ({other})")
    assert not wrong, "\n".join(wrong)


def test_the_client_is_plain_http():
    """The Python client is httpx and the study file reader: no command-line or web framework in it."""
    found = [
        imp
        for imp in imported_names(ROOT / "service" / "client.py", "isolab.service.client")
        if imp.split(".")[0] in ("typer", "rich", *WEB)
    ]
    assert not found, found


def test_no_module_is_over_the_size_limit():
    sizes = {str(p.relative_to(ROOT)): len(p.read_text().splitlines()) for p in project_modules().values()}
    big = {name: n for name, n in sizes.items() if n > MAX_LINES}
    assert not big, f"modules over {MAX_LINES} lines: {big}"


def test_no_folder_holds_more_than_ten_modules():
    folders: dict[Path, int] = {}
    for path in project_modules().values():
        if path.name != "__init__.py":
            folders[path.parent] = folders.get(path.parent, 0) + 1
    crowded = {str(p.relative_to(ROOT)): n for p, n in folders.items() if n > MAX_MODULES_PER_FOLDER}
    assert not crowded, f"folders with more than {MAX_MODULES_PER_FOLDER} modules: {crowded}"


def test_no_private_name_is_imported_from_another_module():
    """What one module uses of another is public: a ``_name`` imported across modules is a seam in hiding."""
    found = []
    for name, path in project_modules().items():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if (
                isinstance(node, ast.ImportFrom)
                and (node.module or "").startswith("isolab")
                and not node.level
            ):
                private = [
                    a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")
                ]
                if private and node.module != name:
                    found.append(f"{name} imports {private} from {node.module}")
    assert not found, "\n".join(found)


def test_the_room_rules_catch_an_upward_import(tmp_path):
    """The room check reads the same graph: an import from a higher room is caught."""
    low = tmp_path / "criteria.py"
    low.write_text("from isolab.studies.results.store import Store\n")
    deps = imported_names(low, "isolab.studies.questions.criteria")
    rank = {room: i for i, room in enumerate(STUDY_ROOMS)}
    assert any(rank[_room(d)] > rank["questions"] for d in deps if _package(d) == "studies")
