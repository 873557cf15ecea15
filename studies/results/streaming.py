"""A study's dataset read from its saved chunks one block at a time, as the file is written.

:func:`streamed_dataset` is the dataset :func:`isolab.studies.results.dataset.to_dataset` builds whole in
memory (with the criteria of :func:`isolab.studies.questions.criteria.add_criteria`), every per-case variable
a dask array with one block per group of consecutive chunks. Written by
:func:`isolab.studies.results.store.write_netcdf`, each block goes into the file as it is read and is let go
after, so the memory the write takes does not grow with the number of cases; and a loader that waits for a
chunk to be saved writes the file while the study's later chunks still compute
(:mod:`isolab.studies.run.landing`).
"""

from __future__ import annotations

import operator
import threading
import uuid
import weakref
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.studies.questions.designs import Design
from isolab.studies.results.compression import deflate_encoding
from isolab.studies.results.dataset import case_layout, check_parameter_names, chunk_dataset, dataset_attrs
from isolab.studies.results.netcdf_locks import netcdf_writing

if TYPE_CHECKING:
    import xarray as xr

STREAM_CHUNK_CACHE_BYTES = 1 << 20
"""Chunk cache (bytes per variable) of the netCDF library while a streamed dataset is written: its blocks
fill whole file chunks, so none waits there half-written (the library's default is 64 MB per variable,
which holds a large study's every chunk until the file closes)."""
BLOCKS_KEY = "isolab_blocks"
"""The encoding key under which a streamed dataset's variables name their block source (see
:func:`write_blocks`); never written to a file (the store writes the encodings it builds itself)."""
_SOURCES: weakref.WeakValueDictionary[str, _ChunkSource] = weakref.WeakValueDictionary()
"""Block sources of the streamed datasets alive in this process, by the token their variables carry."""
BLOCK_CASES = 4096
"""Fewest cases a block of :func:`streamed_dataset` holds by default (consecutive chunks are read together
up to it), so that the file's chunks (one per block) stay large enough to compress and read well."""


def streamed_dataset(
    load_chunk: Callable[[int], Mapping[str, np.ndarray]],
    chunks: Sequence[np.ndarray],
    design: Design,
    *,
    isolator_names: Sequence[str],
    point_names: Sequence[str],
    attrs: Mapping[str, Any] | None = None,
    criteria: Any = None,
    block_cases: int = BLOCK_CASES,
) -> xr.Dataset:
    """A study's dataset whose per-case variables are read from its chunks only when they are computed.

    Equal to ``add_criteria(to_dataset(from_chunks(...), design, ...), criteria)`` (see :func:`to_dataset`,
    :func:`studies.questions.criteria.add_criteria`), but every per-case variable is a dask array with one
    block per
    chunk: ``load_chunk(k)`` gives the arrays of the cases ``chunks[k]`` (as :func:`from_chunks` takes
    them) when a block of chunk ``k`` is computed, and only the last chunk read is kept. Written with
    :func:`studies.results.store.write_netcdf`, each chunk's slice goes into the file as it is read, so the
    memory the write takes does not grow with the number of cases. The coordinates and attributes are
    built at once (the parameter values of every case: 8 bytes a case per numeric parameter).

    Consecutive chunks are read together into blocks of at least ``block_cases`` cases (the file's chunks
    along the cases). A variable is compressed when the first chunk's values of it shrink
    (:func:`isolab.studies.results.compression.shrinks`, as a dataset built in memory judges its first
    values): every value reads back the same either way, only the file's size depends on it.

    Raises:
        ValueError: the chunks do not partition the design's cases, or a parameter name clashes with a
            dimension or variable name. A chunk whose arrays do not fit raises when it is read.
    """
    import dask.array as da
    import xarray as xr
    from dask.highlevelgraph import HighLevelGraph

    n = int(sum(len(c) for c in chunks))
    if design.n_cases != n:
        raise ValueError(f"chunks: {n} cases, but the design has {design.n_cases}")
    all_idx = np.concatenate([np.asarray(c, dtype=np.int64) for c in chunks]) if chunks else np.zeros(0, int)
    if not np.array_equal(np.sort(all_idx), np.arange(n)):
        raise ValueError("chunks: the chunks must cover the cases 0..N-1 exactly once")
    del all_idx
    check_parameter_names(design)
    case_dims, case_coords, order = case_layout(design)
    case_shape = tuple(len(case_coords[d][1]) for d in case_dims) if design.kind == "grid" else (n,)
    # case order along the blocks: the chunks' own order, put in the design's case order when they are
    # not consecutive runs of it
    position = np.concatenate([np.asarray(c, dtype=np.int64) for c in chunks])
    if not np.array_equal(position, np.arange(n)):
        order = np.argsort(position)[order]
    groups = _block_groups([len(c) for c in chunks], block_cases)
    source = _ChunkSource(load_chunk, chunks, groups, isolator_names, point_names, criteria)
    first = source.dataset(0)
    sizes = source.sizes
    # the file's chunks (HDF5) along the cases are the blocks, so that each block written fills whole
    # file chunks: none is ever held half-written (see write_netcdf)
    aligned = all(size == sizes[0] for size in sizes[:-1]) and sizes[-1] <= sizes[0]
    identity = np.array_equal(order, np.arange(n))
    # one task per block reads its chunks and builds every variable's slice; each variable's block takes
    # its own from that task, so the chunks are read once and let go once all their slices are written
    read = f"isolab-chunk-{uuid.uuid4().hex}"
    read_layer: dict[Any, Any] = {(read, j): (source.values, j) for j in range(len(groups))}
    _SOURCES[read] = source
    data_vars: dict[str, xr.Variable] = {}
    for name, var in first.data_vars.items():
        key = f"{read}-{name}"
        inner = (0,) * (var.ndim - 1)
        layer: dict[Any, Any] = {
            (key, j, *inner): (operator.getitem, (read, j), str(name)) for j in range(len(groups))
        }
        graph = HighLevelGraph({read: read_layer, key: layer}, {read: set(), key: {read}})
        blocks = da.Array(
            graph,
            key,
            chunks=(sizes, *((s,) for s in var.shape[1:])),
            dtype=var.dtype,
            meta=np.empty((0,) * var.ndim, dtype=var.dtype),
        )
        if not identity:
            blocks = blocks[order]
        encoding = dict(var.encoding)
        if var.dtype.kind in "fiub":  # judged on the first chunk (see netcdf_encoding)
            encoding.update(deflate_encoding(var.values) or {"zlib": False})
        if case_shape == (n,):
            laid = blocks if identity and aligned else blocks.rechunk({0: sizes[0]})
            if var.dtype.kind != "U":
                encoding["chunksizes"] = (sizes[0], *var.shape[1:])
            if identity and aligned:  # block j of the file is the source's block j: written without dask
                encoding[BLOCKS_KEY] = read
        elif case_shape:  # a grid: whole rows of its first dimension per block
            row = int(np.prod(case_shape[1:]))
            rows = max(1, sizes[0] // row)
            laid = blocks.reshape(case_shape + var.shape[1:]).rechunk({0: rows})
            if var.dtype.kind != "U":
                encoding["chunksizes"] = (rows, *case_shape[1:], *var.shape[1:])
        else:  # no varied parameter: one case
            laid = blocks.reshape(var.shape[1:])
        out = xr.Variable(case_dims + var.dims[1:], laid, attrs=dict(var.attrs))
        out.encoding = encoding
        data_vars[str(name)] = out
    coords: dict[str, xr.Variable] = {
        name: xr.Variable(dims, values, attrs=a) for name, (dims, values, a) in case_coords.items()
    }
    coords.update({str(k): v.variable for k, v in first.coords.items()})
    ds = xr.Dataset(data_vars, coords=coords)
    ds.attrs = dataset_attrs(design, attrs or {})
    if "criteria" in first.attrs:
        ds.attrs["criteria"] = first.attrs["criteria"]
    return ds


class _ChunkSource:
    """Where a streamed dataset's blocks come from: :func:`chunk_dataset` of one chunk, the last one built
    kept (a chunk's blocks of every variable are asked for one after another)."""

    def __init__(
        self,
        load_chunk: Callable[[int], Mapping[str, np.ndarray]],
        chunks: Sequence[np.ndarray],
        groups: Sequence[Sequence[int]],
        isolator_names: Sequence[str],
        point_names: Sequence[str],
        criteria: Any,
    ):
        self.load_chunk, self.chunks, self.groups, self.criteria = load_chunk, chunks, groups, criteria
        self.sizes = tuple(int(sum(len(chunks[k]) for k in g)) for g in groups)  # cases of each block
        self.isolator_names, self.point_names = list(isolator_names), list(point_names)
        self.built = 0  # chunk datasets built so far (each reads its chunk)
        self._last: tuple[int, xr.Dataset] | None = None
        self._block: tuple[int, dict[str, np.ndarray]] | None = None  # the last block's values
        self._lock = threading.Lock()

    def dataset(self, k: int) -> xr.Dataset:
        with self._lock:
            if self._last is None or self._last[0] != k:
                self._last = None  # let the previous chunk go before reading the next
                ds = chunk_dataset(
                    self.load_chunk(k),
                    self.chunks[k],
                    isolator_names=self.isolator_names,
                    point_names=self.point_names,
                    criteria=self.criteria,
                    chunk_index=k,
                )
                self._last = (k, ds)
                self.built += 1
            return self._last[1]

    def values(self, j: int) -> dict[str, np.ndarray]:
        """Block ``j``'s slice of every variable (its chunks, in order): name -> array (case first)."""
        with self._lock:
            if self._block is not None and self._block[0] == j:
                return self._block[1]
        parts = [
            {str(name): np.asarray(v.values) for name, v in self.dataset(k).data_vars.items()}
            for k in self.groups[j]
        ]
        block = parts[0] if len(parts) == 1 else {n: np.concatenate([p[n] for p in parts]) for n in parts[0]}
        with self._lock:
            self._block = (j, block)
        return block


def write_blocks(ds: xr.Dataset, path: str | Path, encoding: Mapping[str, Mapping[str, Any]]) -> None:
    """Write ``ds`` (a :func:`streamed_dataset`) to a new netCDF-4 file at ``path`` with ``encoding``: its
    variables, attributes and in-memory values first, then its dask-backed variables block after block
    along their first dimension, in order (block ``j`` of every variable before block ``j + 1`` of any),
    each block computed in this thread.

    The netCDF lock (:data:`~isolab.studies.results.netcdf_locks.NETCDF_LOCK`) is held only while the file
    is laid out, a block is written and the file is closed: never while a block is computed, which may wait
    for its chunks to be saved (:mod:`isolab.studies.run.landing`). Compressed blocks fill whole file
    chunks (their ``chunksizes``), so the netCDF library's chunk cache is kept small meanwhile."""
    import netCDF4
    from xarray.backends import NetCDF4DataStore
    from xarray.backends.common import ArrayWriter

    writer = ArrayWriter()
    with netcdf_writing():
        store = NetCDF4DataStore.open(str(path), mode="w", format="NETCDF4")
        cache = netCDF4.get_chunk_cache()
    try:
        with netcdf_writing():
            netCDF4.set_chunk_cache(STREAM_CHUNK_CACHE_BYTES, cache[1], cache[2])
            ds.dump_to_store(store, writer=writer, encoding=dict(encoding))
        source = _block_source(ds)
        if source is not None:  # the source's blocks, encoded as xarray encodes them, no graph per block
            _write_source_blocks(ds, source, store, encoding, writer.targets)
        else:
            _write_dask_blocks(writer.sources, writer.targets)
    finally:
        with netcdf_writing():
            try:
                store.close()
            finally:
                netCDF4.set_chunk_cache(*cache)


def _write_dask_blocks(sources: Sequence[Any], targets: Sequence[Any]) -> None:
    """Write each dask array of ``sources`` to its target, block after block along the first dimension
    (block ``j`` of every array before block ``j + 1`` of any), each block computed in this thread outside
    the netCDF lock and written under it."""
    import dask

    for j in range(max((s.numblocks[0] for s in sources), default=0)):
        held = [i for i, s in enumerate(sources) if j < s.numblocks[0]]
        values = dask.compute(
            *[sources[i].blocks[j] for i in held], scheduler="synchronous", optimize_graph=False
        )
        with netcdf_writing():
            for i, value in zip(held, values, strict=True):
                start = int(sum(sources[i].chunks[0][:j]))
                targets[i][start : start + int(sources[i].chunks[0][j]), ...] = value


def _block_source(ds: xr.Dataset) -> _ChunkSource | None:
    """The one block source every dask-backed variable of ``ds`` is laid out from block for block (a
    sampled design's chunks in case order, of one size), or None."""
    lazy = [v for v in ds.variables.values() if v.chunks is not None]
    tokens = {v.encoding.get(BLOCKS_KEY) for v in lazy}
    if len(tokens) != 1 or None in tokens:
        return None
    return _SOURCES.get(str(tokens.pop()))


def _write_source_blocks(
    ds: xr.Dataset,
    source: _ChunkSource,
    store: Any,
    encoding: Mapping[str, Mapping[str, Any]],
    targets: Sequence[Any],
) -> None:
    """Write every dask-backed variable of ``ds`` from ``source``, block after block: each block's values
    (read outside the netCDF lock: they may wait for chunks) encoded by ``store`` as it encodes a whole
    variable, then written to its ``targets`` under the lock."""
    import xarray as xr

    by_name = {str(t.variable_name): t for t in targets}
    lazy = [str(k) for k, v in ds.variables.items() if v.chunks is not None]
    start = 0
    for j, size in enumerate(source.sizes):
        block = source.values(j)
        variables = {}
        for name in lazy:
            var = xr.Variable(ds[name].dims, block[name], attrs=dict(ds[name].attrs))
            var.encoding = dict(encoding[name])
            variables[name] = var
        encoded, _ = store.encode(variables, {})
        with netcdf_writing():
            for name, var in encoded.items():
                by_name[name][start : start + size, ...] = np.asarray(var.data)
        start += size


def _block_groups(sizes: Sequence[int], least: int) -> list[list[int]]:
    """Consecutive chunks (their sizes given) grouped into blocks of at least ``least`` cases (the last
    block may be smaller), chunk indices per block."""
    groups: list[list[int]] = []
    count = 0
    for k, size in enumerate(sizes):
        if not groups or count >= least:
            groups.append([])
            count = 0
        groups[-1].append(k)
        count += int(size)
    return groups
