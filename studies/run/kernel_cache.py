"""Whether the engine's compiled kernels are on disk already, so a command can say when the first run of a
process compiles them (numba, about 10 s, once per machine and engine version).

Numba keeps each ``cache=True`` kernel under ``NUMBA_CACHE_DIR`` (else beside its source, in
``__pycache__``): an index file per kernel lists the compiled signatures, each keyed by the machine's target
and a hash of the kernel's bytecode, and counts only while the source file is unchanged. A kernel is cached
when its index holds an entry for this machine and this bytecode. Only the entry kernels an integrator
calls from Python are read (what they call is compiled, and cached, with them): one small file each.

Each engine version compiles into a folder of its own (``isolab.engine.kernel_cache_folder()``); when a
version first compiles, :func:`tidy_kernel_caches` removes the folders of other versions left unused for
:data:`KEEP_UNUSED_DAYS` days.
"""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

STEPPED = ("euler", "rk4", "exact")
"""Integrators whose cases run through cached driver loops (``engine.integrators.stepping``: one per level,
and at the linear levels one per observer)."""


def entry_kernels(integrator: str | None, fidelity: str | None = None, general: bool = True) -> list[Any]:
    """The numba dispatchers a run with ``integrator`` at ``fidelity`` calls from Python: a stepped method's
    entries per level (every level it integrates for a None ``fidelity``; at the linear levels one per
    observer, ``engine.integrators.stepping.MAPPED`` and ``GENERAL``); every integrator's for a None
    ``integrator`` (a model still to be chosen). Without ``general``, only the drivers a run calls when the
    output map observes every case (``stepping.mapped_cases``)."""
    from isolab.engine.integrators.stepping import ENTRIES as _ENTRIES
    from isolab.engine.integrators.stepping import MAPPED
    from isolab.engine.kernels.dynamics import derivative
    from isolab.engine.kernels.peaks import observe

    drivers = [
        driver
        for (name, at), kernels in _ENTRIES.items()
        if integrator in (None, name) and fidelity in (None, at)
        for code, driver in enumerate(kernels)
        if general or (code == MAPPED and len(kernels) > 1) or at == "nonlinear"
    ]
    if integrator in STEPPED:
        return drivers
    if integrator == "reference":  # scipy's solve_ivp calls the right-hand side and the observer
        return [derivative, observe]
    return drivers + [derivative, observe]


def kernels_cached(
    integrators: Sequence[str | None] = (None,),
    kernels: Sequence[Any] | None = None,
    fidelity: str | None = None,
    general: bool = True,
) -> bool:
    """True when every entry kernel of ``integrators`` at ``fidelity`` (every level for None; without
    ``general``, those of a run whose every case the output map observes: :func:`entry_kernels`; or the
    given numba ``kernels``) has a compiled version on disk for this machine and its current code, so
    nothing is compiled on first use. Reads one small index file per kernel. When numba's cache cannot be
    inspected, answers True (nothing is said)."""
    if kernels is None:
        kernels = [k for name in integrators for k in entry_kernels(name, fidelity, general)]
    for kernel in kernels:
        try:
            cache = kernel._cache
            index = cache._cache_file._load_index()
            _, target, code = cache._index_key(None, kernel.targetctx.codegen())
        except Exception:  # a numba without these internals, or an unreadable index: cannot tell
            continue
        if not any(key[1] == target and key[2] == code for key in index):
            return False
    return True


EXAMPLES_DIR = Path(__file__).resolve().parent.parent / "examples"
"""The example studies (package data): the fidelity and integrator pairs a fresh service warms first."""
WARMUP_DURATION = "0.1 s"
"""Simulated time of the one case a warm-up runs per pair: long enough to call every kernel."""


def example_study(path: Path) -> Any:
    """The example study file at ``path`` with its scene inlined, parsed only (an example is checked by the
    tests; this skips the dry run of its cases)."""
    from isolab.studies.inputs.study import parse_study, read_definition

    data, here = read_definition(path)
    if data.get("scene_file") is not None and data.get("scene") is None:
        data["scene"], _ = read_definition(here / str(data["scene_file"]))
    return parse_study(data)


def example_pairs() -> list[tuple[str, str]]:
    """The (fidelity, integrator) pairs the example studies run at, then the reference pair every study's
    error estimate reruns sampled cases at; each once, in that order."""
    from isolab.studies.run.error_estimate import REFERENCE_PAIR

    pairs: list[tuple[str, str]] = []
    for path in sorted(EXAMPLES_DIR.glob("*.yaml")):
        try:
            sim = example_study(path).simulation
        except Exception:  # a scene file, or an example that is not a study
            continue
        if sim.fidelity is not None and sim.integrator is not None:
            pairs.append((sim.fidelity, sim.integrator))
    pairs.append(REFERENCE_PAIR)
    return list(dict.fromkeys(pairs))


def warmup_definition(fidelity: str, integrator: str) -> str:
    """A one-case study of the article's scriber at ``fidelity`` and ``integrator`` over
    ``WARMUP_DURATION`` of simulated time, as the JSON a chunk task takes."""
    definition = example_study(EXAMPLES_DIR / "lhs-10000.yaml").model_dump(mode="json")
    definition["simulation"] = {"fidelity": fidelity, "integrator": integrator, "duration": WARMUP_DURATION}
    return json.dumps(definition)


def warm_kernels(pairs: Sequence[tuple[str, str]], datasets: bool = False) -> dict[str, float]:
    """Run one short case of each (fidelity, integrator) pair through the chunk task, and at the stepped
    methods' linear levels once more recorded (the general observer's driver), so that this process has
    imported the studies, built its engine structures and loaded (or, on an empty cache, compiled and
    saved) every kernel those pairs call: a later chunk starts computing at once. With ``datasets``, also
    write a small dataset (:func:`warm_datasets`: a worker finishes studies, and its first would otherwise
    pay xarray's and netCDF4's first use). Returns seconds per pair (``"<fidelity>/<integrator>"``, and
    ``"datasets"``) and, under ``"pid"``, this process's id."""
    import numpy as np

    from isolab.engine import simulate
    from isolab.studies.inputs.study import study_from_json
    from isolab.studies.run.fanout import run_chunk

    took: dict[str, float] = {"pid": float(os.getpid())}
    for fidelity, integrator in pairs:
        t0 = time.perf_counter()
        definition = warmup_definition(fidelity, integrator)
        run_chunk(definition, [0])  # a case the output map observes, at the linear levels
        if integrator in STEPPED and fidelity != "nonlinear":  # and one the general observer does
            study = study_from_json(definition)
            _, _, dt = study.simulation.engine_choice()
            simulate(study.batch(np.zeros(1, dtype=np.int64)), fidelity, integrator, dt, record=[0])
        took[f"{fidelity}/{integrator}"] = time.perf_counter() - t0
    if datasets:
        t0 = time.perf_counter()
        warm_datasets()
        took["datasets"] = time.perf_counter() - t0
    return took


def warm_datasets() -> bool:
    """Write a two-case dataset through the store's netCDF writer into a temporary folder: the first
    dataset a process builds and writes otherwise pays for xarray's and netCDF4's imports and their
    first-use lookups (the array libraries xarray looks for, the backends), 0.4-0.6 s of CPU. Whether it
    was written: a full temporary disk or any other failure only leaves the first study to pay that
    (logged, not raised)."""
    import tempfile

    import numpy as np
    import xarray as xr

    from isolab.studies.results.store import write_netcdf

    ds = xr.Dataset(
        {
            "peak": (("case", "axis"), np.zeros((2, 3)), {"units": "m"}),
            "status": ("case", np.zeros(2, dtype=np.int8)),
        },
        coords={"case": np.arange(2), "axis": ["x", "y", "z"]},
    )
    try:
        with tempfile.TemporaryDirectory(prefix="isolab-warm-") as folder:
            write_netcdf(ds, Path(folder) / "warm.nc")
    except Exception as err:  # the warm-up only saves the first study its time
        logging.getLogger(__name__).warning("could not write a dataset at warm-up: %s", err)
        return False
    return True


def warmup_plan() -> tuple[list[tuple[str, str]], bool]:
    """The pairs a service warms at start (:func:`example_pairs`) and whether the kernels they call are all
    in the cache already (the worker task that plans the warm-up); when they are not, the kernel cache
    folders of other engine versions long unused are removed (:func:`tidy_kernel_caches`)."""
    pairs = example_pairs()
    cached = all(kernels_cached([integrator], fidelity=fidelity) for fidelity, integrator in pairs)
    if not cached:  # this engine version compiles: the folders of versions long unused go
        tidy_kernel_caches()
    return pairs, cached


KEEP_UNUSED_DAYS = 14.0
"""Days the kernel cache folder of another engine version is kept after its last use (a few hundred MB each
for a developer who edits the engine; a reinstall of the same version uses its folder again)."""
ENGINE_HASH_NAME = re.compile(r"[0-9a-f]{12}")
"""How ``isolab.engine`` names a kernel cache folder (:func:`isolab.engine.engine_source_hash`)."""
REMOVING = ".removing-"
"""A folder renamed for removal: ``.<name>.removing-<pid>``, out of every process's way at once."""


def last_used(folder: Path) -> float:
    """When a process last used the kernel cache ``folder`` (POSIX time, s): the latest change of the folder
    or anything in it, or read of a file in it (numba reads a kernel's index file when it loads the kernel;
    a file's access time moves at least daily on a file system mounted ``relatime``, the default). 0 when
    nothing in it can be read."""
    newest = 0.0
    for root, _, files in os.walk(folder):
        try:
            newest = max(newest, os.stat(root).st_mtime)  # a folder's access time moves when it is listed
        except OSError:
            continue
        for name in files:
            try:
                info = os.stat(os.path.join(root, name))
            except OSError:  # removed meanwhile
                continue
            newest = max(newest, info.st_mtime, info.st_atime)
    return newest


def remove_unused_kernel_caches(
    parent: Path, current: Path, keep_days: float = KEEP_UNUSED_DAYS, now: float | None = None
) -> list[Path]:
    """Remove the folders of ``parent`` named like an engine version's kernel cache, other than ``current``,
    that no process has used for ``keep_days`` days (:func:`last_used`), and what an interrupted removal
    left. A folder is first renamed (a process still reading it finds nothing and compiles afresh), then
    deleted; every error is ignored (another process may remove the same folder at the same time). Returns
    the folders removed."""
    now = time.time() if now is None else now
    removed: list[Path] = []
    try:
        entries = sorted(parent.iterdir())
    except OSError:
        return removed
    for folder in entries:
        if REMOVING in folder.name and folder.is_dir():  # an interrupted removal's leftover
            shutil.rmtree(folder, ignore_errors=True)
            continue
        if not ENGINE_HASH_NAME.fullmatch(folder.name) or folder.name == current.name or not folder.is_dir():
            continue
        if now - last_used(folder) < keep_days * 86400.0:
            continue
        doomed = parent / f".{folder.name}{REMOVING}{os.getpid()}"
        try:
            folder.rename(doomed)
        except OSError:  # another process got there first, or the folder cannot be moved
            continue
        shutil.rmtree(doomed, ignore_errors=True)
        removed.append(folder)
    return removed


def tidy_kernel_caches(keep_days: float = KEEP_UNUSED_DAYS) -> list[Path]:
    """Remove the kernel cache folders of other engine versions unused for ``keep_days`` days, beside this
    version's default folder (``<XDG_CACHE_HOME or ~/.cache>/isolab/numba``). Nothing is removed when the
    user chose the folder (``NUMBA_CACHE_DIR``). Called when this engine version is about to compile: about
    once per version and machine. Returns the folders removed."""
    from isolab.engine import default_kernel_cache_folder, kernel_cache_folder

    current = kernel_cache_folder()
    try:
        if current.resolve() != default_kernel_cache_folder().resolve():
            return []
    except OSError:
        return []
    return remove_unused_kernel_caches(current.parent, current, keep_days)
