"""Which variables of a stored dataset are compressed: those that shrink.

A study's dataset is written with zlib at level 1 and the byte-shuffle filter (any netCDF-4 reader opens
it, no filter plugin needed), but only on the variables that shrink by at least half under it: the
outputs that are constant or missing for every case (a scene without points, a yes/no that never
happens), the statuses, the labels. The peaks and times of the cases themselves are float64 numbers with
little redundancy: zlib takes 10-15 % off them at about 80 % of the write's time, so they are stored as
they are (measured on the 10,000-case Latin hypercube of ``studies/examples/lhs-10000.yaml``: every
variable compressed 8.1 MB in 0.20 s of CPU, these only 9.3 MB in 0.06 s, none 11.4 MB in 0.04 s).
Which variables are compressed changes only the file's size: every value reads back the same.
"""

from __future__ import annotations

import zlib
from typing import Any

import numpy as np

DEFLATE = {"zlib": True, "complevel": 1, "shuffle": True}
"""The netCDF encoding of a compressed variable."""
PROBE_VALUES = 4096
"""Values of a variable that :func:`shrinks` compresses to judge it: :data:`PROBE_RUNS` runs of
consecutive values (in storage order) spread evenly over it, the first at its start. On the datasets of
10,000 and 100,000 cases of the end-to-end benchmark and of an optimisation, 4,096 values judge every
variable as the 8,192 first values did, in 7 ms of CPU for 34 variables instead of 16 (fewer values
compress less well: 2,048 judged a variable that shrinks to 0.47 of its bytes as not shrinking)."""
PROBE_RUNS = 4
SHRINK_BELOW = 0.5
"""A variable is compressed when its probe compresses to less than this fraction of its bytes."""


def shrinks(values: np.ndarray) -> bool:
    """Whether a variable's ``values`` shrink below :data:`SHRINK_BELOW` of their bytes under
    :data:`DEFLATE`, judged on :data:`PROBE_VALUES` of them (:func:`probe_values`), byte-shuffled as the
    netCDF filter does."""
    probe = probe_values(np.asarray(values))
    if probe.size == 0:
        return False
    raw = probe.view(np.uint8).reshape(probe.size, probe.itemsize).T.tobytes()  # the shuffle filter
    return len(zlib.compress(raw, DEFLATE["complevel"])) < SHRINK_BELOW * len(raw)


def probe_values(values: np.ndarray) -> np.ndarray:
    """The values of ``values`` (flattened in storage order) that :func:`shrinks` judges: all of them up to
    :data:`PROBE_VALUES`, else :data:`PROBE_RUNS` runs of consecutive values spread evenly from the start
    (a variable whose first cases repeat but whose others do not is judged on both)."""
    flat = values.reshape(-1)
    if flat.size <= PROBE_VALUES:
        return np.ascontiguousarray(flat)
    run = PROBE_VALUES // PROBE_RUNS
    starts = np.linspace(0, flat.size - run, PROBE_RUNS).astype(np.int64)
    return np.concatenate([flat[s : s + run] for s in starts])


def deflate_encoding(values: np.ndarray | None) -> dict[str, Any]:
    """The compression part of a numeric variable's netCDF encoding: :data:`DEFLATE` when its ``values``
    shrink (:func:`shrinks`) or are not at hand (None: a streamed variable, written block by block,
    is always compressed), else none."""
    return dict(DEFLATE) if values is None or shrinks(values) else {}
