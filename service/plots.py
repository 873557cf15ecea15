"""Figures of the service as PNG bytes (matplotlib's Agg canvas; no pyplot state, safe in threads).

* :func:`case_png`: the article's figures for one case: c.g. translation x, y, z (mm), base rotation
  rx, ry, rz (mrad) and the isolator forces along X, Y and Z (N, one line per isolator), stacked over time.
* :func:`study_png`: an output against one varied parameter (a line per isolator type, or a scatter for
  sampled studies) or two (a heat map per isolator type, or a coloured scatter).

Inputs are SI; lengths are drawn in mm and angles in mrad.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from isolab.studies import AXES, ROTATIONS

#: SI unit -> (unit drawn, factor from SI)
DISPLAY_UNITS: dict[str, tuple[str, float]] = {"m": ("mm", 1e3), "rad": ("mrad", 1e3)}
DPI = 100


@dataclass
class Series:
    """One column of a case table: its name, values (one per case, SI) and SI unit ("" for text)."""

    name: str
    values: np.ndarray
    unit: str


def format_value(value: Any) -> str:
    """A parameter value for a title or tick label (4 significant digits for numbers)."""
    if isinstance(value, float | np.floating):
        return f"{float(value):.4g}"
    return str(value)


def _display(unit: str) -> tuple[str, float]:
    return DISPLAY_UNITS.get(unit, (unit, 1.0))


def _label(name: str, unit: str) -> str:
    shown, _ = _display(unit)
    return f"{name} ({shown})" if shown and shown != "1" else name


def _png(fig: Figure) -> bytes:
    canvas = FigureCanvasAgg(fig)
    buf = io.BytesIO()
    canvas.print_png(buf)
    return buf.getvalue()


def case_png(
    time: np.ndarray,
    displacement: np.ndarray,
    rotation: np.ndarray,
    isolator_force: np.ndarray,
    isolator_names: list[str],
    title: str = "",
) -> bytes:
    """Stacked time plots of one case.

    Args:
        time: (T,) s.
        displacement: (T, 3) c.g. displacement, m (drawn in mm).
        rotation: (T, 3) base rotation about X, Y, Z, rad (drawn in mrad).
        isolator_force: (T, n, 3) dynamic force of each isolator along X, Y, Z, N.
        isolator_names: n labels.
        title: figure title.
    """
    t = np.asarray(time, dtype=float)
    fig = Figure(figsize=(9, 12), dpi=DPI, layout="constrained")
    panels = fig.subplots(5, 1, sharex=True)
    ax = panels[0]
    for k, a in enumerate(AXES):
        ax.plot(t, np.asarray(displacement)[:, k] * 1e3, label=a)
    ax.set_ylabel("c.g. translation (mm)")
    ax.legend(loc="upper right", ncols=3, fontsize="small")
    ax = panels[1]
    for k, r in enumerate(ROTATIONS):
        ax.plot(t, np.asarray(rotation)[:, k] * 1e3, label=r)
    ax.set_ylabel("rotation (mrad)")
    ax.legend(loc="upper right", ncols=3, fontsize="small")
    force = np.asarray(isolator_force)
    for k, a in enumerate(AXES):
        ax = panels[2 + k]
        for j, name in enumerate(isolator_names):
            ax.plot(t, force[:, j, k], label=str(name))
        ax.set_ylabel(f"isolator force {a.upper()} (N)")
        if k == 0 and isolator_names:
            ax.legend(loc="upper right", ncols=min(4, len(isolator_names)), fontsize="small")
    panels[-1].set_xlabel("time (s)")
    for ax in panels:
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return _png(fig)


# ------------------------------------------------------------------------------------------ studies
def _levels(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sorted distinct values, index of each value among them)."""
    return np.unique(values, return_inverse=True)


def _reduce(values: np.ndarray, how: str) -> float:
    v = np.asarray(values, dtype=float)
    if v.size == 0 or np.all(np.isnan(v)):
        return float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        reducers: dict[str, Any] = {"max": np.nanmax, "min": np.nanmin, "mean": np.nanmean}
        return float(reducers[how](v))


def _reduced(keys: list[np.ndarray], y: np.ndarray, how: str) -> tuple[list[np.ndarray], np.ndarray, bool]:
    """Combine the cases that share the same keys: (level arrays per key, reduced y over the key grid,
    whether any cell combined several cases)."""
    levels, index = zip(*(_levels(k) for k in keys), strict=True)
    shape = tuple(len(lv) for lv in levels)
    flat = np.ravel_multi_index(tuple(index), shape)
    out = np.full(int(np.prod(shape)), np.nan)
    combined = False
    order = np.argsort(flat, kind="stable")
    cells, starts = np.unique(flat[order], return_index=True)
    for cell, chunk in zip(cells, np.split(order, starts[1:]), strict=True):
        out[cell] = _reduce(y[chunk], how)
        combined |= chunk.size > 1
    return list(levels), out.reshape(shape), combined


def _ticks(ax: Any, which: str, levels: np.ndarray, unit: str) -> np.ndarray:
    """Positions for the levels: the values themselves for numbers, 0..k-1 with labels for text."""
    if levels.dtype.kind in "USO":
        pos = np.arange(len(levels), dtype=float)
        getattr(ax, f"set_{which}ticks")(pos, [str(v) for v in levels])
        return pos
    pos = np.asarray(levels, dtype=float) * _display(unit)[1]
    if len(pos) <= 12:
        getattr(ax, f"set_{which}ticks")(pos, [format_value(v) for v in pos])
    return pos


def study_png(
    y: Series,
    x: Series,
    x2: Series | None = None,
    group: Series | None = None,
    sampled: bool = False,
    reduce: str = "max",
    title: str = "",
) -> bytes:
    """An output ``y`` against a varied parameter ``x`` (and ``x2``), one line or panel per ``group``.

    Cases that share the plotted values (other parameters varied too) are combined with ``reduce``
    (max, min or mean), and the axis label says so. Sampled studies are drawn as scatter plots.
    """
    yv = np.asarray(y.values, dtype=float) * _display(y.unit)[1]
    groups = [None] if group is None else [str(g) for g in _levels(np.asarray(group.values))[0]]

    def members(g: str | None) -> np.ndarray:
        if g is None or group is None:
            return np.arange(yv.size)
        return np.flatnonzero(np.asarray(group.values).astype(str) == g)

    ylabel = _label(y.name, y.unit)
    if x2 is None:
        fig = Figure(figsize=(8, 5), dpi=DPI, layout="constrained")
        ax = fig.subplots()
        combined = False
        xt = np.asarray(x.values)
        text_x = xt.dtype.kind in "USO"
        all_levels = _levels(xt)[0]
        pos_all = _ticks(ax, "x", all_levels, x.unit)
        for g in groups:
            idx = members(g)
            if sampled:
                px = (
                    np.searchsorted(all_levels, xt[idx]).astype(float)
                    if text_x
                    else xt[idx].astype(float) * _display(x.unit)[1]
                )
                ax.scatter(px, yv[idx], s=12, alpha=0.7, label=g)
                continue
            (lv,), ry, comb = _reduced([xt[idx]], yv[idx], reduce)
            combined |= comb
            px = pos_all[np.searchsorted(all_levels, lv)]
            ax.plot(px, ry, marker="o", label=g)
        ax.set_xlabel(_label(x.name, x.unit))
        ax.set_ylabel(ylabel + (f", {reduce} over other parameters" if combined else ""))
        ax.grid(True, alpha=0.3)
        if group is not None:
            ax.legend(title=group.name)
        if title:
            ax.set_title(title)
        return _png(fig)

    n = len(groups)
    fig = Figure(figsize=(min(5.5 * n, 16), 4.8), dpi=DPI, layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, n, squeeze=False)[0])
    xt, x2t = np.asarray(x.values), np.asarray(x2.values)
    for ax, g in zip(axes, groups, strict=True):
        idx = members(g)
        if sampled:
            px = _numeric_or_rank(xt[idx], x.unit)
            py = _numeric_or_rank(x2t[idx], x2.unit)
            art = ax.scatter(px, py, c=yv[idx], s=14, cmap="viridis")
            label = ylabel
        else:
            (lx, ly), grid, comb = _reduced([xt[idx], x2t[idx]], yv[idx], reduce)
            px = _ticks(ax, "x", lx, x.unit)
            py = _ticks(ax, "y", ly, x2.unit)
            art = ax.pcolormesh(
                _edges(px), _edges(py), np.ma.masked_invalid(grid.T), cmap="viridis", shading="flat"
            )
            label = ylabel + (f", {reduce} over other parameters" if comb else "")
        fig.colorbar(art, ax=ax, label=label)
        ax.set_xlabel(_label(x.name, x.unit))
        ax.set_ylabel(_label(x2.name, x2.unit))
        if g is not None and group is not None:
            ax.set_title(f"{group.name} = {g}")
    if title:
        fig.suptitle(title)
    return _png(fig)


def _numeric_or_rank(values: np.ndarray, unit: str) -> np.ndarray:
    if values.dtype.kind in "USO":
        return _levels(values)[1].astype(float)
    return values.astype(float) * _display(unit)[1]


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres (half-way between neighbours; unit width for a single cell)."""
    c = np.asarray(centres, dtype=float)
    if c.size == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = (c[1:] + c[:-1]) / 2.0
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])
