"""The kernel cache folders of other engine versions go after two weeks unused; nothing else is touched."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from isolab.engine import engine_source_hash
from isolab.studies.run.kernel_cache import KEEP_UNUSED_DAYS, last_used, remove_unused_kernel_caches

DAY = 86400.0
NOW = time.time()


def _version_folder(
    parent: Path, name: str, changed_days_ago: float, read_days_ago: float | None = None
) -> Path:
    """A kernel cache folder as numba leaves it (a sub-folder per source folder, an index and a data file per
    kernel), last changed ``changed_days_ago`` and its index last read ``read_days_ago`` days before NOW."""
    folder = parent / name
    sub = folder / "engine_integrators_abc123"
    sub.mkdir(parents=True)
    changed = NOW - changed_days_ago * DAY
    read = changed if read_days_ago is None else NOW - read_days_ago * DAY
    for file, atime in (("stepping.run-12.py311.nbi", read), ("stepping.run-12.py311.1.nbc", changed)):
        (sub / file).write_bytes(b"\0" * 64)
        os.utime(sub / file, (atime, changed))
    for path in (sub, folder):
        os.utime(path, (NOW, changed))  # a folder's access time is not a use
    return folder


def test_last_use_is_the_latest_change_or_read_of_a_file(tmp_path: Path) -> None:
    changed = _version_folder(tmp_path, "aaaaaaaaaaaa", changed_days_ago=30)
    read = _version_folder(tmp_path, "bbbbbbbbbbbb", changed_days_ago=30, read_days_ago=2)
    assert abs(last_used(changed) - (NOW - 30 * DAY)) < 1.0
    assert abs(last_used(read) - (NOW - 2 * DAY)) < 1.0
    assert last_used(tmp_path / "missing") == 0.0


def test_only_other_versions_unused_for_two_weeks_go(tmp_path: Path) -> None:
    current = _version_folder(tmp_path, "cccccccccccc", changed_days_ago=400)  # never removed, however old
    old = _version_folder(tmp_path, "0123456789ab", changed_days_ago=KEEP_UNUSED_DAYS + 1)
    recent = _version_folder(tmp_path, "ba9876543210", changed_days_ago=KEEP_UNUSED_DAYS - 1)
    still_read = _version_folder(tmp_path, "dddddddddddd", changed_days_ago=90, read_days_ago=1)
    foreign = _version_folder(tmp_path, "my-notes", changed_days_ago=90)  # not an engine version's name
    leftover = _version_folder(tmp_path, ".eeeeeeeeeeee.removing-4242", changed_days_ago=0)
    (tmp_path / "ffffffffffff").write_text("a file, not a cache folder")
    os.utime(tmp_path / "ffffffffffff", (NOW - 90 * DAY, NOW - 90 * DAY))

    removed = remove_unused_kernel_caches(tmp_path, current, now=NOW)

    assert removed == [old]
    assert not old.exists() and not leftover.exists()
    assert current.is_dir() and recent.is_dir() and still_read.is_dir() and foreign.is_dir()
    assert (tmp_path / "ffffffffffff").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["cccccccccccc", "ba9876543210", "dddddddddddd", "my-notes", "ffffffffffff"]
    )
    # a second process finds nothing more to do; a shorter keep removes the recent one too
    assert remove_unused_kernel_caches(tmp_path, current, now=NOW) == []
    assert remove_unused_kernel_caches(tmp_path, current, keep_days=KEEP_UNUSED_DAYS - 2, now=NOW) == [recent]
    assert remove_unused_kernel_caches(tmp_path / "missing", current, now=NOW) == []


_TIDY = """
import json, os
from isolab.engine import kernel_cache_folder
from isolab.studies.run.kernel_cache import tidy_kernel_caches, warmup_plan
how = os.environ["TIDY_HOW"]
removed = tidy_kernel_caches() if how == "tidy" else []
cached = warmup_plan()[1] if how == "plan" else None
removed = [str(p) for p in removed]
print(json.dumps({"folder": str(kernel_cache_folder()), "removed": removed, "cached": cached}))
"""


def _tidy_in_a_fresh_process(tmp_path: Path, how: str, **env: str) -> dict:
    environ = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    environ.update(XDG_CACHE_HOME=str(tmp_path), TIDY_HOW=how, **env)
    out = subprocess.run(
        [sys.executable, "-c", _TIDY], env=environ, capture_output=True, text=True, timeout=120, check=True
    )
    return json.loads(out.stdout.splitlines()[-1])


def test_a_new_engine_version_removes_old_folders_beside_its_own(tmp_path: Path) -> None:
    parent = tmp_path / "isolab" / "numba"
    old = _version_folder(parent, "0123456789ab", changed_days_ago=60)
    recent = _version_folder(parent, "ba9876543210", changed_days_ago=3)
    # the service's warm-up plan finds this version's kernels missing (an empty cache): old folders go
    shown = _tidy_in_a_fresh_process(tmp_path, "plan")
    assert shown["folder"] == str(parent / engine_source_hash()) and shown["cached"] is False
    assert not old.exists() and recent.is_dir()


def test_a_folder_the_user_chose_leaves_every_folder_alone(tmp_path: Path) -> None:
    parent = tmp_path / "isolab" / "numba"
    old = _version_folder(parent, "0123456789ab", changed_days_ago=60)
    chosen = parent / "cccccccccccc"  # even one beside the others
    shown = _tidy_in_a_fresh_process(tmp_path, "tidy", NUMBA_CACHE_DIR=str(chosen))
    assert shown == {"folder": str(chosen), "removed": [], "cached": None}
    assert old.is_dir()
    shown = _tidy_in_a_fresh_process(tmp_path, "tidy")  # the default folder: the old one goes
    assert shown["removed"] == [str(old)] and not old.exists()
