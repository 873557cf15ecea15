"""Where studies live: the study files (one netCDF dataset per study, chunk results while it runs) beside
the SQLite catalog that finds them (:mod:`isolab.studies.results.catalog`).

Layout under ``root``::

    catalog.sqlite               the catalog (table ``studies``), WAL mode
    studies/<id>.nc              a finished study's dataset
    studies/<id>.chunks/<k>.npz  results of chunk k of a study still running (removed once the .nc exists)
    studies/<id>.chunks/plan.npz the case indices of every chunk, so a resumed run splits the same way
    studies/<id>.results/        what is derived from the dataset and cached beside it (sensitivity JSON)
    service.lock                 held (``flock``) by the one service that runs this store's studies

A study id is a uuid4 hex string (32 lowercase hex digits); every id is checked before it becomes part of a
path, so no path outside ``root`` can be named. Files are written atomically: to a hidden temporary file in
the same directory, flushed and fsynced, then renamed over the target with ``os.replace``; a write that
fails half-way leaves the previous file untouched and removes its temporary file.

:class:`Store` keeps both: the files itself, the catalog through a
:class:`~isolab.studies.results.catalog.Catalog` (whose methods it passes on: a study is added with
:meth:`Store.register`, read back as a :class:`~isolab.studies.results.records.StudyRecord`, listed with a
:class:`~isolab.studies.results.records.StudyFilter`), so one object names a study's row and its files.
Both open files per call, so one :class:`Store` can be shared between threads; listing and filtering run in
SQL and never open a netCDF file. Datasets are built by :mod:`isolab.studies.results.dataset` and written
here (:func:`write_netcdf`, with :func:`netcdf_encoding`).

Writing and reading chunks and writing datasets record their durations in the timing journal when one is
configured (see :func:`isolab.studies.results.timings.record_timing`).
"""

from __future__ import annotations

import builtins
import contextlib
import datetime
import errno
import fcntl
import logging
import os
import shutil
import socket
import tempfile
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.engine.results import OK, STATUS_NAMES
from isolab.studies.inputs.definitions import stored_definition
from isolab.studies.inputs.study import Study
from isolab.studies.results.catalog import (
    CATALOG_FILE,
    STATUSES,
    STUDY_ID,
    Catalog,
    CatalogUnavailable,
    StudyNotFound,
    check_id,
    utc_now,
)
from isolab.studies.results.compression import deflate_encoding
from isolab.studies.results.netcdf_locks import NETCDF_LOCK, netcdf_writing
from isolab.studies.results.records import StudyFilter, StudyRecord, isolator_types
from isolab.studies.results.timings import record_timing

if TYPE_CHECKING:  # xarray and netCDF4 load with the first dataset written or read
    import xarray as xr

log = logging.getLogger(__name__)

__all__ = [
    "LOCK_FILE",
    "STATUSES",
    "CatalogUnavailable",
    "Store",
    "StoreFull",
    "StoreInUse",
    "StoreLock",
    "StudyFilter",
    "StudyNotFound",
    "StudyRecord",
    "atomic_path",
    "check_id",
    "check_writable",
    "is_no_space",
    "copy_atomic",
    "failures",
    "netcdf_encoding",
    "new_file_mode",
    "utc_now",
    "write_netcdf",
]
"""The catalog's names callers reach through the store (``STATUSES``, ``StudyNotFound``, ``check_id``,
``utc_now``) live in :mod:`isolab.studies.results.catalog`."""


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(target: Path, durable: bool = True) -> Iterator[Path]:
    """Yield a hidden temporary path next to ``target``; on success fsync it (unless not ``durable``: a
    file that is written again when lost, whose later fsync makes it durable) and rename it over
    ``target``.

    If the body raises, the temporary file is removed and ``target`` is left as it was.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        if durable:
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    _fsync_dir(target.parent)


RESERVE_FILE = ".reserve"
"""A file of :data:`RESERVE_BYTES` under a store's root, held back for a full disk: a write that fails for
want of space deletes it, so that the catalog can still record why the study failed."""
RESERVE_BYTES = 1024 * 1024
_NO_SPACE = (errno.ENOSPC, errno.EDQUOT)
_MB = 1e6


def remove_tree(folder: Path, attempts: int = 5) -> None:
    """Remove ``folder`` and everything in it, while a study that is being stopped may still write there:
    a file that vanishes under the walk (an atomic write's temporary renamed away) is not an error, and a
    file written meanwhile is taken on the next attempt."""
    for _ in range(attempts):
        try:
            shutil.rmtree(folder)
        except FileNotFoundError:
            pass
        except OSError as err:
            if not folder.exists() or err.errno not in (errno.ENOTEMPTY, errno.ENOENT):
                raise
        if not folder.exists():
            return
        time.sleep(0.05)
    shutil.rmtree(folder, ignore_errors=True)


class StoreFull(OSError):
    """A store write failed for want of space (errno ENOSPC); the message says what needed how much.
    Built as ``StoreFull(errno.ENOSPC, message, path)`` (so it crosses Dask's pickling whole)."""

    def __str__(self) -> str:
        return str(self.strerror)


def is_no_space(err: BaseException | None) -> bool:
    """``err`` (or an exception it was raised from) is a write that failed for want of space."""
    seen = 0
    while err is not None and seen < 10:
        if isinstance(err, OSError) and err.errno in _NO_SPACE:
            return True
        err, seen = err.__cause__ or err.__context__, seen + 1
    return False


def _free_bytes(directory: Path) -> int:
    try:
        return int(shutil.disk_usage(directory).free)
    except OSError:
        return -1


def _store_full(what: str, needed: int, directory: Path, err: BaseException) -> StoreFull:
    free = _free_bytes(directory)
    text = (
        f"no space left on device: {what} needs about {max(needed / _MB, 0.1):.1f} MB, "
        f"{max(free, 0) / _MB:.1f} MB free in {directory} ({type(err).__name__}: {err})"
    )
    return StoreFull(errno.ENOSPC, text, str(directory))


def check_writable(root: str | Path) -> str | None:
    """None when the store under ``root`` takes writes: a 64 kB file can be written and synced there, and
    the reserve (:data:`RESERVE_FILE`) is in place or can be put back. Else why not."""
    root = Path(root)
    try:
        with tempfile.NamedTemporaryFile(dir=root, prefix=".health-") as f:
            f.write(b"\0" * 65536)
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        if exc.errno in _NO_SPACE:
            return f"no space left on device: {_free_bytes(root) / _MB:.1f} MB free in {root}"
        return f"{type(exc).__name__}: {exc}"
    if not _put_reserve(root):
        return (
            f"no space left on device: the store's {RESERVE_BYTES / _MB:.0f} MB reserve cannot be put back, "
            f"{_free_bytes(root) / _MB:.1f} MB free in {root}"
        )
    return None


def _put_reserve(root: Path) -> bool:
    """Create the reserve file when it is missing; False when there is no room for it."""
    target = root / RESERVE_FILE
    if target.is_file() and target.stat().st_size >= RESERVE_BYTES:
        return True
    try:
        with atomic_path(target) as tmp, open(tmp, "wb") as f:
            f.write(b"\0" * RESERVE_BYTES)
    except OSError:
        return False
    return True


def netcdf_encoding(ds: xr.Dataset) -> dict[str, dict[str, Any]]:
    """Per-variable netCDF encoding: NaN ``_FillValue`` on floats, int8/-1 for yes/no, zlib on the numbers
    that shrink under it (:mod:`isolab.studies.results.compression`; every streamed one).

    A variable backed by a dask array (:func:`isolab.studies.results.streaming.streamed_dataset`) keeps the
    ``chunksizes`` its encoding names (its blocks) and the compression it was judged to need (``zlib``,
    from its first values; every one that does not say); the others get the netCDF library's default
    chunking."""
    enc: dict[str, dict[str, Any]] = {}
    for name, var in ds.variables.items():
        e: dict[str, Any] = {}
        if var.dtype.kind in "fiub" and var.ndim > 0:
            if var.chunks is None:
                e.update(deflate_encoding(var.values))
            elif var.encoding.get("zlib", True):
                e.update(deflate_encoding(None))
            chunks = var.encoding.get("chunksizes") if var.chunks is not None else None
            if chunks is not None and len(chunks) == var.ndim and 0 < min(*chunks, *var.shape):
                e["chunksizes"] = tuple(
                    min(int(c), int(size)) for c, size in zip(chunks, var.shape, strict=True)
                )
        if var.encoding.get("dtype") == "int8" and "_FillValue" in var.encoding:
            e.update(dtype="int8", _FillValue=np.int8(var.encoding["_FillValue"]))
        elif var.dtype.kind == "f" and name not in ds.dims:
            e["_FillValue"] = np.nan
        elif name in ds.dims or var.dtype.kind in "iuUSO":
            e["_FillValue"] = None
        enc[str(name)] = e
    return enc


def write_netcdf(ds: xr.Dataset, path: str | Path, durable: bool = True) -> Path:
    """Write ``ds`` to ``path`` atomically (see :func:`atomic_path`, ``durable``), with
    :func:`netcdf_encoding`.

    A dataset with variables backed by dask arrays (:func:`isolab.studies.results.streaming.streamed_dataset`)
    is written block after block, each computed here, in this thread
    (:func:`isolab.studies.results.streaming.write_blocks`; never on a Dask cluster this process may be
    part of)."""
    from isolab.studies.results.streaming import write_blocks

    path = Path(path)
    encoding = netcdf_encoding(ds)
    streamed = any(v.chunks is not None for v in ds.variables.values())
    with atomic_path(path, durable) as tmp:
        try:
            if streamed:
                write_blocks(ds, tmp, encoding)
            else:
                with netcdf_writing():
                    ds.to_netcdf(tmp, format="NETCDF4", engine="netcdf4", encoding=encoding)
        except Exception as err:
            # netCDF-C reports a full disk as anything (EACCES, "HDF error"): ask the file system. The
            # size needed is the data uncompressed, an upper bound.
            needed = int(ds.nbytes)
            free = _free_bytes(path.parent)
            if is_no_space(err) or 0 <= free < min(needed, RESERVE_BYTES):
                raise _store_full(f"writing {path.name}", needed, path.parent, err) from err
            raise
    return path


def new_file_mode() -> int:
    """The mode ``open()`` gives a new file: 0o666 less the process's umask (a temporary file from
    :func:`tempfile.mkstemp` is 0o600 whatever the umask). Read from ``/proc`` where it says, so the umask
    is never changed, even for a moment."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            mask = next(int(line.split()[1], 8) for line in f if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0o022)
        os.umask(mask)
    return 0o666 & ~mask


def copy_atomic(source: str | Path, target: str | Path) -> Path:
    """Copy a file to ``target`` atomically, with the mode a new file gets (:func:`new_file_mode`): a file
    written for the user, not one of the store's own."""
    target = Path(target)
    with atomic_path(target) as tmp:
        shutil.copyfile(source, tmp)
        os.chmod(tmp, new_file_mode())
    return target


LOCK_FILE = "service.lock"
"""File under a store's root that the service running its studies holds locked (see :class:`StoreLock`)."""


class StoreInUse(RuntimeError):
    """Another process (another isolab service) holds the store's lock."""


class StoreLock:
    """The lock of one store: one service at a time runs a store's studies.

    :meth:`acquire` takes an exclusive ``flock`` on ``<root>/service.lock`` without waiting, and writes the
    holder (pid, host, time) into the file for the message another service gets; :meth:`release` lets it
    go. The kernel releases it when the process ends however it ends (``kill -9`` included), so a killed
    service never blocks its restart. Within one process the lock is counted: a second :meth:`acquire` of
    the same root (the ``serve`` command, then the app it starts) shares it.
    """

    _held: dict[Path, tuple[int, int]] = {}  # root -> (file descriptor, holders in this process)
    _guard = threading.Lock()

    def __init__(self, root: str | Path):
        self.root = Path(root).resolve()
        self.path = self.root / LOCK_FILE
        self._acquired = False

    def acquire(self) -> StoreLock:
        """Take the lock (the root is created if missing). Raises StoreInUse naming the holder."""
        if self._acquired:
            return self
        with StoreLock._guard:
            fd, count = StoreLock._held.get(self.root, (-1, 0))
            if count == 0:
                self.root.mkdir(parents=True, exist_ok=True)
                try:
                    fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
                except OSError as exc:  # a read-only store: nothing can run on it; /health says so
                    log.warning("cannot lock %s (%s): starting without the one-service guard", self.path, exc)
                    return self
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "unknown process"
                    os.close(fd)
                    raise StoreInUse(
                        f"the data directory {self.root} is in use by another isolab service ({holder}); "
                        "stop that service first, or give this one another data directory"
                    ) from None
                except BaseException:
                    os.close(fd)
                    raise
                with contextlib.suppress(OSError):  # the note is for people; a full disk must not stop us
                    note = f"pid {os.getpid()} on {socket.gethostname()}, since {utc_now()}\n".encode()
                    os.ftruncate(fd, 0)
                    os.pwrite(fd, note, 0)
            StoreLock._held[self.root] = (fd, count + 1)
            self._acquired = True
        return self

    def release(self) -> None:
        """Let the lock go (the file stays; the last holder in this process closes it)."""
        if not self._acquired:
            return
        with StoreLock._guard:
            fd, count = StoreLock._held[self.root]
            if count <= 1:
                del StoreLock._held[self.root]
                os.close(fd)  # closing the file releases the flock
            else:
                StoreLock._held[self.root] = (fd, count - 1)
            self._acquired = False

    def __enter__(self) -> StoreLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


class Store:
    """The study files under ``root`` and, through :attr:`catalog`, the SQLite catalog beside them."""

    def __init__(self, root: str | Path, *, catalog: bool = True):
        """Open (or create) the store under ``root``. With ``catalog=False`` only the files are used (a
        Dask worker that saves chunks and writes datasets): nothing is created, the catalog is not
        opened (:attr:`catalog` is None)."""
        self.root = Path(root).resolve()
        self.studies_dir = self.root / "studies"
        self.catalog_path = self.root / CATALOG_FILE
        self.catalog: Catalog | None = None
        if not catalog:
            return
        self.studies_dir.mkdir(parents=True, exist_ok=True)
        self.catalog = Catalog(self.catalog_path)
        _put_reserve(self.root)

    def restore_reserve(self) -> bool:
        """Put the reserve file back if it is missing (each study run starts so); False when there is no
        room for it."""
        return _put_reserve(self.root)

    def release_reserve(self) -> bool:
        """Delete the reserve file (after a write failed for want of space), so that the catalog has room
        to record the failure; :func:`check_writable` (``/health``) puts it back once there is room.
        False when it was gone already."""
        try:
            (self.root / RESERVE_FILE).unlink()
        except FileNotFoundError:
            return False
        return True

    # ------------------------------------------------------------------------------------- catalog
    def _rows(self) -> Catalog:
        if self.catalog is None:
            raise RuntimeError(f"the store under {self.root} was opened without its catalog")
        return self.catalog

    def register(self, study: Study) -> str:
        """Add ``study`` to the catalog, queued; returns its new id. Its record: the stored definition
        (:func:`~isolab.studies.inputs.definitions.stored_definition`), name, planned cases (an
        optimisation's budget), varied parameters, isolator types and simulation settings."""
        sim = study.simulation
        return self.create(
            stored_definition(study),
            name=study.name,
            n_cases=int(study.planned_cases),
            parameters=builtins.list(study.design().names),
            isolator_types=isolator_types(study),
            fidelity=sim.fidelity,
            integrator=sim.integrator,
            dt=sim.dt,
        )

    def create(
        self,
        definition: Mapping[str, Any] | str,
        *,
        name: str,
        n_cases: int,
        parameters: Sequence[str] = (),
        isolator_types: Sequence[str] = (),
        fidelity: str | None = None,
        integrator: str | None = None,
        dt: float | None = None,
        status: str = "queued",
        created: str | datetime.datetime | None = None,
    ) -> str:
        """Add a study to the catalog from its fields; returns its new id (see :meth:`Catalog.create`;
        :meth:`register` adds a :class:`~isolab.studies.inputs.study.Study`)."""
        return self._rows().create(
            definition,
            name=name,
            n_cases=n_cases,
            parameters=parameters,
            isolator_types=isolator_types,
            fidelity=fidelity,
            integrator=integrator,
            dt=dt,
            status=status,
            created=created,
        )

    def get(self, study_id: str) -> StudyRecord:
        """The catalog record of a study (see :meth:`Catalog.get`). Raises StudyNotFound."""
        return self._rows().get(study_id)

    def update(self, study_id: str, **fields: Any) -> None:
        """Set catalog fields of a study (see :meth:`Catalog.update`). Raises StudyNotFound."""
        self._rows().update(study_id, **fields)

    def list(
        self, where: StudyFilter | None = None, *, limit: int = 50, offset: int = 0
    ) -> builtins.list[StudyRecord]:
        """Catalog records, newest first, filtered in SQL (see :meth:`Catalog.list`)."""
        return self._rows().list(where, limit=limit, offset=offset)

    def count(self, where: StudyFilter | None = None) -> int:
        """Number of catalog records matching ``where`` (see :meth:`Catalog.count`)."""
        return self._rows().count(where)

    def delete(self, study_id: str) -> bool:
        """Remove a study's catalog row, dataset file and chunks. False if there was nothing to remove."""
        found = self._rows().delete(study_id)
        path = self.path(study_id)
        if path.exists():
            path.unlink()
            found = True
        chunk_dir = self.chunk_dir(study_id)
        if chunk_dir.exists():
            remove_tree(chunk_dir)
            found = True
        shutil.rmtree(self.results_dir(study_id), ignore_errors=True)
        return found

    # --------------------------------------------------------------------------------------- files
    def path(self, study_id: str) -> Path:
        """Path of a study's netCDF file (whether or not it exists)."""
        return self.studies_dir / f"{check_id(study_id)}.nc"

    def results_dir(self, study_id: str) -> Path:
        """Directory of what is derived from a study's dataset and kept beside it (sensitivity analyses;
        whether or not it exists). Removed with the study."""
        return self.studies_dir / f"{check_id(study_id)}.results"

    def write_dataset(self, study_id: str, ds: xr.Dataset, staged: bool = False) -> Path:
        """Write a study's dataset atomically to :meth:`path`, or with ``staged`` to :meth:`staged_path`
        (for :meth:`publish_dataset` to complete; not fsynced: publishing fsyncs the whole file, and a
        run that stops before writes it again)."""
        t0, c0 = time.perf_counter(), time.thread_time()
        path = write_netcdf(
            ds, self.staged_path(study_id) if staged else self.path(study_id), durable=not staged
        )
        seconds, cpu_s = time.perf_counter() - t0, time.thread_time() - c0
        record_timing(
            "write_dataset", study_id=study_id, seconds=seconds, cpu_s=cpu_s, bytes=path.stat().st_size
        )
        return path

    def staged_path(self, study_id: str) -> Path:
        """Where a study's dataset is written before its last variables are added (in its chunk folder:
        a run that stops before :meth:`publish_dataset` leaves it there, and the next run writes it again)."""
        return self.chunk_dir(study_id) / "dataset.nc"

    def publish_dataset(self, study_id: str, extra: xr.Dataset) -> Path:
        """Add ``extra``'s variables (no dimensions of their own) and attributes to the staged dataset
        (:meth:`staged_path`), with :func:`netcdf_encoding`, and move it to :meth:`path` atomically."""
        staged, path = self.staged_path(study_id), self.path(study_id)
        t0 = time.perf_counter()
        with netcdf_writing():
            extra.to_netcdf(
                staged, mode="a", format="NETCDF4", engine="netcdf4", encoding=netcdf_encoding(extra)
            )
        with open(staged, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(staged, path)
        _fsync_dir(path.parent)
        record_timing("publish_dataset", study_id=study_id, seconds=time.perf_counter() - t0)
        return path

    def open_dataset(self, study_id: str) -> xr.Dataset:
        """A study's dataset, loaded into memory (the file is closed again). Raises StudyNotFound."""
        import xarray as xr

        path = self.path(study_id)
        if not path.exists():
            raise StudyNotFound(study_id)
        with NETCDF_LOCK, xr.open_dataset(path) as ds:
            return ds.load()

    def dataset_ids(self) -> builtins.list[str]:
        """Ids of the studies that have a dataset file, sorted."""
        return sorted(p.stem for p in self.studies_dir.glob("*.nc") if STUDY_ID.fullmatch(p.stem))

    # -------------------------------------------------------------------------------------- chunks
    def chunk_dir(self, study_id: str) -> Path:
        """Directory of a study's per-chunk results."""
        return self.studies_dir / f"{check_id(study_id)}.chunks"

    def save_chunk(self, study_id: str, chunk_index: int, arrays: Mapping[str, np.ndarray]) -> Path:
        """Save one chunk's result arrays atomically as ``<id>.chunks/<k>.npz`` (no pickled objects)."""
        k = _chunk_index(chunk_index)
        path = self.chunk_dir(study_id) / f"{k}.npz"
        t0 = time.perf_counter()
        _save_npz(path, arrays)
        record_timing(
            "save_chunk",
            study_id=study_id,
            chunk=k,
            seconds=time.perf_counter() - t0,
            bytes=path.stat().st_size,
        )
        return path

    def load_chunks(
        self, study_id: str, fields: Sequence[str] | None = None
    ) -> dict[int, dict[str, np.ndarray]]:
        """Every saved chunk of a study: chunk index -> arrays (only ``fields`` when given, see
        :meth:`load_chunk`)."""
        t0 = time.perf_counter()
        out = {k: self.load_chunk(study_id, k, fields) for k in self.done_chunks(study_id)}
        record_timing("load_chunks", study_id=study_id, n_chunks=len(out), seconds=time.perf_counter() - t0)
        return out

    def load_chunk(
        self, study_id: str, chunk_index: int, fields: Sequence[str] | None = None
    ) -> dict[str, np.ndarray]:
        """One saved chunk's arrays; with ``fields``, only those it has (the others are not even read, so
        a study's statuses come back without its outputs). Raises FileNotFoundError if it is not saved."""
        k = _chunk_index(chunk_index)
        with np.load(self.chunk_dir(study_id) / f"{k}.npz", allow_pickle=False) as z:
            return {name: z[name] for name in z.files if fields is None or name in fields}

    def done_chunks(self, study_id: str) -> set[int]:
        """Indices of the chunks of a study whose results are saved."""
        d = self.chunk_dir(study_id)
        if not d.is_dir():
            return set()
        return {int(p.stem) for p in d.glob("*.npz") if p.stem.isdigit()}

    def save_chunk_plan(self, study_id: str, chunks: Sequence[np.ndarray]) -> None:
        """Save how a study's cases are split into chunks (so a resumed run splits them the same way)."""
        _save_npz(
            self.chunk_dir(study_id) / "plan.npz",
            {f"c{k}": np.asarray(c, dtype=np.int64) for k, c in enumerate(chunks)},
        )

    def has_chunk_plan(self, study_id: str) -> bool:
        """Whether this process sees the saved chunk split of a study: a Dask worker that does shares the
        store with the runner, and saves chunks and writes the dataset itself."""
        return (self.chunk_dir(study_id) / "plan.npz").is_file()

    def load_chunk_plan(self, study_id: str) -> builtins.list[np.ndarray] | None:
        """The saved chunk split of a study, or None."""
        path = self.chunk_dir(study_id) / "plan.npz"
        if not path.exists():
            return None
        with np.load(path, allow_pickle=False) as z:
            return [z[f"c{k}"] for k in range(len(z.files))]

    def clear_chunks(self, study_id: str) -> None:
        """Remove a study's per-chunk results and plan."""
        d = self.chunk_dir(study_id)
        if d.exists():
            t0 = time.perf_counter()
            shutil.rmtree(d)
            record_timing("clear_chunks", study_id=study_id, seconds=time.perf_counter() - t0)

    def sweep_chunks(self) -> builtins.list[str]:
        """Remove the per-chunk results of every study that is done (a run removes them right after it
        marks its study done, so a service stopped in between leaves them behind); the ids swept."""
        swept = []
        for folder in sorted(self.studies_dir.glob("*.chunks")):
            study_id = folder.name.removesuffix(".chunks")
            if not STUDY_ID.fullmatch(study_id):
                continue
            with contextlib.suppress(StudyNotFound):  # a folder the catalog does not know: left alone
                if self.get(study_id).status == "done":
                    self.clear_chunks(study_id)
                    swept.append(study_id)
        return swept


def _chunk_index(k: Any) -> int:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or int(k) < 0:
        raise ValueError(f"chunk_index: {k!r} is not a non-negative integer")
    return int(k)


def _save_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    checked = {}
    for name, value in arrays.items():
        a = np.asarray(value)
        if a.dtype.kind == "O":
            raise ValueError(f"arrays[{name!r}]: object arrays cannot be saved; use a numeric or str dtype")
        checked[str(name)] = a
    try:
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, **checked)  # type: ignore[arg-type]  # numpy's stub types the keywords as flags
    except OSError as err:
        if is_no_space(err):
            needed = sum(a.nbytes for a in checked.values())
            raise _store_full(f"writing {path.parent.name}/{path.name}", needed, path.parent, err) from err
        raise


def failures(path: str | Path) -> str:
    """What went wrong in a study's dataset file: how many cases have each status other than ok, and the
    message of the first of them (``"12 tipping; case 0: statically unstable: ..."``). Empty when every
    case is ok."""
    import xarray as xr

    with NETCDF_LOCK, xr.open_dataset(path) as ds:
        status = np.asarray(ds["status"].values, dtype=np.int8).reshape(-1)
        bad = np.flatnonzero(status != OK)
        if bad.size == 0:
            return ""
        # the first message only (a large study's messages are not all read)
        first = np.unravel_index(int(bad[0]), ds["status"].shape)
        message = str(ds["message"][first].values)
    counts = ", ".join(
        f"{int((status == code).sum())} {name}"
        for code, name in enumerate(STATUS_NAMES)
        if code != OK
        if (status == code).any()
    )
    return f"{counts}; case {int(bad[0])}: {message}"
