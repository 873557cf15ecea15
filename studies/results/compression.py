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
PROBE_VALUES = 8192
"""Values of a variable (its first, in storage order) that :func:`shrinks` compresses to judge it."""
SHRINK_BELOW = 0.5
"""A variable is compressed when its probe compresses to less than this fraction of its bytes."""


def shrinks(values: np.ndarray) -> bool:
    """Whether a variable's ``values`` shrink below :data:`SHRINK_BELOW` of their bytes under
    :data:`DEFLATE`, judged on their first :data:`PROBE_VALUES` values, byte-shuffled as the netCDF
    filter does."""
    probe = np.ascontiguousarray(np.asarray(values).reshape(-1)[:PROBE_VALUES])
    if probe.size == 0:
        return False
    raw = probe.view(np.uint8).reshape(probe.size, probe.itemsize).T.tobytes()  # the shuffle filter
    return len(zlib.compress(raw, DEFLATE["complevel"])) < SHRINK_BELOW * len(raw)


def deflate_encoding(values: np.ndarray | None) -> dict[str, Any]:
    """The compression part of a numeric variable's netCDF encoding: :data:`DEFLATE` when its ``values``
    shrink (:func:`shrinks`) or are not at hand (None: a streamed variable, written block by block,
    is always compressed), else none."""
    return dict(DEFLATE) if values is None or shrinks(values) else {}
