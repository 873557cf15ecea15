"""One kernel cache per machine and engine version: the folder isolab.engine chooses before numba loads."""

from __future__ import annotations

import multiprocessing
import os
import shutil
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from isolab.engine import ENGINE_FOLDER, default_kernel_cache_folder, engine_source_hash, kernel_cache_folder

_SHOW = "import isolab.engine as e, numba; print(e.kernel_cache_folder()); print(numba.config.CACHE_DIR)"


def _without_cache_dir(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    return {**env, **extra}


def _show(env: dict[str, str]) -> list[str]:
    out = subprocess.run([sys.executable, "-c", _SHOW], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_the_folder_changes_when_any_engine_source_changes(tmp_path: Path) -> None:
    copy = tmp_path / "engine"
    shutil.copytree(ENGINE_FOLDER, copy, ignore=shutil.ignore_patterns("__pycache__"))
    env = {"XDG_CACHE_HOME": str(tmp_path / "cache")}
    before = default_kernel_cache_folder(copy, env)
    assert before == tmp_path / "cache" / "isolab" / "numba" / engine_source_hash(copy)
    assert engine_source_hash(copy) == engine_source_hash(ENGINE_FOLDER)  # a copy is the same engine
    # an edit in a module no kernel is defined in (numba itself would not notice it) gives a new folder
    params = copy / "kernels" / "params.py"
    params.write_text(params.read_text() + "\n# edited\n")
    after = default_kernel_cache_folder(copy, env)
    assert after != before and after.parent == before.parent
    # a new module counts too; a compiled file beside the sources does not
    (copy / "integrators" / "new_method.py").write_text("NAME = 'new'\n")
    assert default_kernel_cache_folder(copy, env) not in (before, after)
    newest = default_kernel_cache_folder(copy, env)
    (copy / "__pycache__").mkdir()
    (copy / "__pycache__" / "x.py").write_text("stale = True\n")
    assert default_kernel_cache_folder(copy, env) == newest


def test_without_xdg_the_folder_is_under_the_home_cache(tmp_path: Path) -> None:
    folder = default_kernel_cache_folder(ENGINE_FOLDER, {"HOME": str(tmp_path)})
    assert folder == tmp_path / ".cache" / "isolab" / "numba" / engine_source_hash()


def test_numba_caches_in_the_chosen_folder(tmp_path: Path) -> None:
    folder, numba_dir = _show(_without_cache_dir(XDG_CACHE_HOME=str(tmp_path)))
    expected = tmp_path / "isolab" / "numba" / engine_source_hash()
    assert Path(folder) == expected and Path(numba_dir) == expected


def test_a_users_numba_cache_dir_wins(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    folder, numba_dir = _show(_without_cache_dir(XDG_CACHE_HOME=str(tmp_path), NUMBA_CACHE_DIR=str(mine)))
    assert Path(folder) == mine and Path(numba_dir) == mine


def test_numba_imported_first_still_caches_in_the_chosen_folder(tmp_path: Path) -> None:
    code = "import numba; " + _SHOW
    env = _without_cache_dir(XDG_CACHE_HOME=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    folder, numba_dir = out.stdout.split()
    assert folder == numba_dir == str(tmp_path / "isolab" / "numba" / engine_source_hash())


def _worker_folder() -> str:
    import isolab.engine

    return str(isolab.engine.kernel_cache_folder())


def test_a_spawned_worker_process_shares_the_folder() -> None:
    # Dask's LocalCluster spawns its workers: they inherit the environment and import isolab.engine afresh
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        assert pool.submit(_worker_folder).result(timeout=120) == str(kernel_cache_folder())
    assert os.environ["NUMBA_CACHE_DIR"] == str(kernel_cache_folder())
