"""Experiment designs: which parameter values each case of a study takes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Design:
    """The cases of a study.

    Attributes:
        kind: "grid" (full factorial: one dataset dimension per parameter) or "sampled" (a ``case``
            dimension with each parameter as a coordinate along it).
        names: parameter names, in order (for a grid, the order of the dataset dimensions; the last
            varies fastest, as in ``numpy.ndindex``).
        values: per parameter, an array of shape (n_cases,) with the value each case takes (float, or
            str for a categorical parameter such as ``isolator_type``).
        levels: for a grid, per parameter, the array of its distinct levels in order; empty otherwise.
        paths: per parameter, the path into the scene it sets.
        units: per parameter, its SI unit ("" for categorical / dimensionless).
    """

    kind: str
    names: list[str]
    values: dict[str, np.ndarray]
    levels: dict[str, np.ndarray]
    paths: dict[str, str]
    units: dict[str, str]

    @property
    def n_cases(self) -> int:
        if not self.names:
            return 1
        return int(len(self.values[self.names[0]]))

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape (one entry per parameter) or (n_cases,) for a sampled design."""
        if self.kind == "grid":
            return tuple(len(self.levels[n]) for n in self.names)
        return (self.n_cases,)
