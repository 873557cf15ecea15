"""Figures of the service as PNG bytes (matplotlib's Agg canvas; no pyplot state, safe in threads).

* :func:`case_png`: the article's figures for one case: c.g. translation x, y, z, base rotation rx, ry,
  rz and the isolator forces along X, Y and Z (one line per isolator), stacked over time
  (:func:`case_figure` is the same as a matplotlib Figure).
* :func:`study_png`: an output against one varied parameter (a line per isolator type, or a scatter for
  sampled studies) or two (a heat map per isolator type, or a coloured scatter); :func:`study_figure` is
  the same as a matplotlib Figure.

Inputs are SI. A study's parameters are drawn in the unit the study was written in (``0.5 g .. 2 g`` on a
g axis, a log-scaled range on a log axis); outputs and traces in a unit read easily at their magnitude
(mm or um, mrad, N or kN: :func:`isolab.studies.units.readable_unit`).
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from isolab.studies import AXES, ROTATIONS
from isolab.studies.questions.designs import Design
from isolab.studies.units import readable_unit, shown_in

if TYPE_CHECKING:  # matplotlib and the case table load when a figure is drawn
    from matplotlib.figure import Figure

    from isolab.studies.results.cases import CaseColumns

DPI = 100


@dataclass
class Series:
    """One column of a case table.

    Attributes:
        name: column name.
        values: one per case, SI (or text).
        unit: SI unit ("" for text, "1" dimensionless).
        display_unit: the unit to draw it in (a parameter's ``display_units``: ``"g"``, ``"%"``); "" picks
            one readable at the values' magnitude (:func:`isolab.studies.units.readable_unit`).
        scale: "linear" or "log" (a parameter whose range was log-scaled is drawn on a log axis).
        long_name: what it holds, for the axis label ("" uses ``name``).
    """

    name: str
    values: np.ndarray
    unit: str
    display_unit: str = ""
    scale: str = "linear"
    long_name: str = ""

    def shown(self) -> Shown:
        """The values in the unit they are drawn in, with that unit and the axis label."""
        v = np.asarray(self.values)
        if v.dtype.kind in "USO":
            return Shown(self.name, v, "", self.long_name or self.name, False)
        if self.display_unit:
            values, unit = shown_in(v, self.unit, self.display_unit)
        else:
            unit, one = readable_unit(self.unit, v)
            values = v.astype(np.float64) / one
        unit = "" if unit in ("", "1") else unit
        finite = values[np.isfinite(values)]
        log = self.scale == "log" and finite.size > 0 and bool(np.all(finite > 0))
        return Shown(self.name, values, unit, self.long_name or self.name, log)


@dataclass
class Shown:
    """A :class:`Series` as drawn: values in ``unit``, on a log axis or not."""

    name: str
    values: np.ndarray
    unit: str
    long_name: str
    log: bool

    @property
    def label(self) -> str:
        """Axis label: the long name and the unit drawn, ``peak ... displacement, y (mm)``."""
        return f"{self.long_name} ({self.unit})" if self.unit else self.long_name

    @property
    def heading(self) -> str:
        """The column name and the unit drawn, for titles: ``peak_displacement_y (mm)``."""
        return f"{self.name} ({self.unit})" if self.unit else self.name


def series(table: CaseColumns, name: str) -> Series:
    """The column ``name`` of a case table as a :class:`Series`: a parameter with the unit the study was
    written in and its scale, an output with its long name."""
    return Series(
        name,
        table.data[name],
        table.units[name],
        display_unit=table.display_units.get(name, ""),
        scale=table.scales.get(name, "linear"),
        long_name=table.long_names.get(name, ""),
    )


def format_value(value: Any) -> str:
    """A parameter value for a title or tick label (4 significant digits for numbers)."""
    if isinstance(value, float | np.floating):
        return f"{float(value):.4g}"
    return str(value)


def new_figure(width: float, height: float) -> Figure:
    """An empty matplotlib figure of ``width`` x ``height`` inches at :data:`DPI`, constrained layout."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=DPI, layout="constrained")


def figure_png(fig: Figure) -> bytes:
    """A matplotlib figure as PNG bytes (drawn by Agg, without pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    buf = io.BytesIO()
    canvas.print_png(buf)
    return buf.getvalue()


def case_figure(
    time: np.ndarray,
    displacement: np.ndarray,
    rotation: np.ndarray,
    isolator_force: np.ndarray,
    isolator_names: list[str],
    title: str = "",
) -> Figure:
    """Stacked time plots of one case, each quantity in a unit read easily at its magnitude
    (:func:`isolab.studies.units.readable_unit`: mm or um, mrad, N or kN).

    Args:
        time: (T,) s.
        displacement: (T, 3) c.g. displacement, m.
        rotation: (T, 3) base rotation about X, Y, Z, rad.
        isolator_force: (T, n, 3) dynamic force of each isolator along X, Y, Z, N.
        isolator_names: n labels.
        title: figure title.
    """
    t = np.asarray(time, dtype=float)
    fig = new_figure(9, 12)
    panels = fig.subplots(5, 1, sharex=True)
    ax = panels[0]
    shift = np.asarray(displacement, dtype=float)
    unit, one = readable_unit("m", shift)
    for k, a in enumerate(AXES):
        ax.plot(t, shift[:, k] / one, label=a)
    ax.set_ylabel(f"c.g. translation ({unit})")
    ax.legend(loc="upper right", ncols=3, fontsize="small")
    ax = panels[1]
    turn = np.asarray(rotation, dtype=float)
    unit, one = readable_unit("rad", turn)
    for k, r in enumerate(ROTATIONS):
        ax.plot(t, turn[:, k] / one, label=r)
    ax.set_ylabel(f"rotation ({unit})")
    ax.legend(loc="upper right", ncols=3, fontsize="small")
    force = np.asarray(isolator_force, dtype=float)
    unit, one = readable_unit("N", force)  # one unit for the three force panels
    for k, a in enumerate(AXES):
        ax = panels[2 + k]
        for j, name in enumerate(isolator_names):
            ax.plot(t, force[:, j, k] / one, label=str(name))
        ax.set_ylabel(f"isolator force {a.upper()} ({unit})")
        if k == 0 and isolator_names:
            ax.legend(loc="upper right", ncols=min(4, len(isolator_names)), fontsize="small")
    panels[-1].set_xlabel("time (s)")
    for ax in panels:
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig


def case_png(
    time: np.ndarray,
    displacement: np.ndarray,
    rotation: np.ndarray,
    isolator_force: np.ndarray,
    isolator_names: list[str],
    title: str = "",
) -> bytes:
    """:func:`case_figure` as PNG bytes."""
    return figure_png(case_figure(time, displacement, rotation, isolator_force, isolator_names, title))


def parameters_text(values: dict[str, Any], design: Design) -> str:
    """A case's parameter values in the units its study was written in, for a title:
    ``isolator_type=air, stage_y_acceleration=2 g, isolator_zeta=10 %``."""
    parts = []
    for name, value in values.items():
        if isinstance(value, str | np.str_) or name not in design.units:
            parts.append(f"{name}={format_value(value)}")
            continue
        shown, unit = shown_in([value], design.units[name], design.display_units.get(name, ""))
        unit = "" if unit in ("", "1") else f" {unit}"
        parts.append(f"{name}={format_value(float(shown[0]))}{unit}")
    return ", ".join(parts)


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


def _log_axis(ax: Any, which: str, series: Shown) -> bool:
    """Put the ``which`` axis on a log scale when ``series`` was drawn on one and its values allow."""
    if not series.log:
        return False
    getattr(ax, f"set_{which}scale")("log")
    return True


def _ticks(ax: Any, which: str, levels: np.ndarray, series: Shown) -> np.ndarray:
    """Positions for the levels: the values themselves for numbers (a tick at each of up to 12 levels),
    0..k-1 with labels for text."""
    if levels.dtype.kind in "USO":
        pos = np.arange(len(levels), dtype=float)
        getattr(ax, f"set_{which}ticks")(pos, [str(v) for v in levels])
        return pos
    pos = np.asarray(levels, dtype=float)
    if len(pos) <= 12:
        getattr(ax, f"set_{which}ticks")(pos, [format_value(v) for v in pos])
        if series.log:  # no decade labels over the levels' own
            from matplotlib.ticker import NullFormatter

            getattr(ax, f"{which}axis").set_minor_formatter(NullFormatter())
    return pos


def point_alpha(n: int) -> float:
    """Opacity of each of ``n`` scatter points: 0.8 up to 300 points, then falling as 1/sqrt(n) (0.14 at
    10,000) so that dense regions show as darker rather than as one blot; never below 0.05."""
    return float(np.clip(0.8 * np.sqrt(300.0 / max(n, 1)), 0.05, 0.8))


def point_size(n: int) -> float:
    """Marker area (points^2) of each of ``n`` scatter points: 12 up to 1,000 points, smaller beyond."""
    return float(np.clip(12.0 * np.sqrt(1000.0 / max(n, 1)), 2.0, 12.0))


def study_figure(
    y: Series,
    x: Series,
    x2: Series | None = None,
    group: Series | None = None,
    sampled: bool = False,
    reduce: str = "max",
    title: str = "",
) -> Figure:
    """An output ``y`` against a varied parameter ``x`` (and ``x2``), one line or panel per ``group``, as
    a matplotlib Figure (:func:`study_png` draws it).

    Parameters are drawn in the unit the study was written in (:attr:`Series.display_unit`, ``g`` or
    ``%``), on a log axis when their range was log-scaled; outputs in a unit read easily at their
    magnitude (mm, um, kN, mrad: :func:`isolab.studies.units.readable_unit`). Axis labels are the long
    name and that unit. Cases that share the plotted values (other parameters varied too) are combined
    with ``reduce`` (max, min or mean), and the axis label says so. Sampled studies are drawn as scatter
    plots whose points grow fainter and smaller as they grow many (:func:`point_alpha`).
    """
    ys, xs = y.shown(), x.shown()
    yv = np.asarray(ys.values, dtype=float)
    groups = [None] if group is None else [str(g) for g in _levels(np.asarray(group.values))[0]]

    def members(g: str | None) -> np.ndarray:
        if g is None or group is None:
            return np.arange(yv.size)
        return np.flatnonzero(np.asarray(group.values).astype(str) == g)

    if x2 is None:
        fig = new_figure(8, 5)
        ax = fig.subplots()
        combined = False
        xt = np.asarray(xs.values)
        text_x = xt.dtype.kind in "USO"
        _log_axis(ax, "x", xs)
        all_levels = _levels(xt)[0]
        pos_all = _ticks(ax, "x", all_levels, xs)
        alpha, size = point_alpha(yv.size), point_size(yv.size)
        for g in groups:
            idx = members(g)
            if sampled:
                px = np.searchsorted(all_levels, xt[idx]).astype(float) if text_x else xt[idx].astype(float)
                ax.scatter(px, yv[idx], s=size, alpha=alpha, linewidths=0, label=g)
                continue
            (lv,), ry, comb = _reduced([xt[idx]], yv[idx], reduce)
            combined |= comb
            px = pos_all[np.searchsorted(all_levels, lv)]
            ax.plot(px, ry, marker="o", label=g)
        ax.set_xlabel(xs.label)
        ax.set_ylabel(ys.label + (f", {reduce} over other parameters" if combined else ""))
        ax.grid(True, alpha=0.3, which="both" if xs.log else "major")
        if group is not None:
            legend = ax.legend(title=group.name)
            for handle in legend.legend_handles:
                if handle is not None:
                    handle.set_alpha(1.0)
        ax.set_title(_title(title, ys, xs))
        return fig

    x2s = x2.shown()
    n = len(groups)
    fig = new_figure(min(max(5.5 * n, 6.5), 16), 5.2)
    axes = np.atleast_1d(fig.subplots(1, n, squeeze=False)[0])
    xt, x2t = np.asarray(xs.values), np.asarray(x2s.values)
    for ax, g in zip(axes, groups, strict=True):
        idx = members(g)
        log_x, log_y = _log_axis(ax, "x", xs), _log_axis(ax, "y", x2s)
        if sampled:
            px = _numeric_or_rank(xt[idx])
            py = _numeric_or_rank(x2t[idx])
            art = ax.scatter(
                px,
                py,
                c=yv[idx],
                s=point_size(idx.size) * 1.2,
                alpha=max(point_alpha(idx.size), 0.3),
                linewidths=0,
                cmap="viridis",
            )
            label = ys.label
        else:
            (lx, ly), grid, comb = _reduced([xt[idx], x2t[idx]], yv[idx], reduce)
            px = _ticks(ax, "x", lx, xs)
            py = _ticks(ax, "y", ly, x2s)
            art = ax.pcolormesh(
                _edges(px, log_x),
                _edges(py, log_y),
                np.ma.masked_invalid(grid.T),
                cmap="viridis",
                shading="flat",
            )
            label = ys.label + (f", {reduce} over other parameters" if comb else "")
        bar = fig.colorbar(art, ax=ax, label=label)
        if bar.solids is not None:  # the colour scale at full strength, whatever the points' opacity
            bar.solids.set_alpha(1.0)
        ax.set_xlabel(xs.label)
        ax.set_ylabel(x2s.label)
        if g is not None and group is not None:
            ax.set_title(f"{group.name} = {g}")
    fig.suptitle(_title(title, ys, xs, x2s), fontsize="medium")
    return fig


def study_png(
    y: Series,
    x: Series,
    x2: Series | None = None,
    group: Series | None = None,
    sampled: bool = False,
    reduce: str = "max",
    title: str = "",
) -> bytes:
    """:func:`study_figure` as PNG bytes."""
    return figure_png(study_figure(y, x, x2, group, sampled, reduce, title))


def _title(title: str, y: Shown, x: Shown, x2: Shown | None = None) -> str:
    """The study's title over ``y (unit) against x (unit)[ and x2 (unit)]``."""
    against = f"{x.heading}" + (f" and {x2.heading}" if x2 is not None else "")
    what = f"{y.heading} against {against}" if x2 is None else f"{y.heading}\nagainst {against}"
    return f"{title}\n{what}" if title else what


def _numeric_or_rank(values: np.ndarray) -> np.ndarray:
    if values.dtype.kind in "USO":
        return _levels(values)[1].astype(float)
    return values.astype(float)


def _edges(centres: np.ndarray, log: bool = False) -> np.ndarray:
    """Cell edges around sorted centres: half-way between neighbours (geometrically on a log axis), the
    end cells as wide as their neighbours; unit width (a factor sqrt(10) on a log axis) for a single cell."""
    c = np.asarray(centres, dtype=float)
    if log:
        return np.exp(_edges(np.log(c))) if c.size > 1 else np.array([c[0] / 10**0.5, c[0] * 10**0.5])
    if c.size == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = (c[1:] + c[:-1]) / 2.0
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


# ------------------------------------------------------------------------------------ floor spectra
def _label_line(ax: Any, name: str, x: float, y: float, color: str) -> None:
    """Name a criterion line at its right end (``x``, ``y`` in data units), outside the axes if need be."""
    ax.annotate(
        name,
        (x, y),
        xytext=(3, 0),
        textcoords="offset points",
        va="center",
        fontsize="x-small",
        color=color,
        annotation_clip=False,
    )


def floor_velocity_png(spectra: dict[str, Any], title: str = "") -> bytes:
    """One-third-octave RMS velocity of a point per floor axis (a panel each), one stepped line per
    isolator type, the floor's own spectrum dashed, against the VC curves (and the ISO workshop and office
    lines where flat), log-log, um/s.

    Args:
        spectra: what :func:`isolab.studies.answers.floor_response.velocity_spectra` returns (SI).
        title: figure title (default: the point's name).
    """
    from isolab.studies.questions.floor import ISO_LEVELS, ISO_RANGE, VC_LEVELS, VC_RANGE

    edges = np.asarray(spectra["band_edges"], dtype=float)  # (21,) Hz
    BAND_LOWER, BAND_UPPER = edges[:-1], edges[1:]
    um = 1e6
    fig = new_figure(15, 5.2)
    panels = fig.subplots(1, 3, sharey=True)
    floor = np.asarray(spectra["floor"], dtype=float)
    everything = [floor[floor > 0] * um]
    for v in spectra["velocity"].values():
        v = np.asarray(v, dtype=float)
        everything.append(v[np.isfinite(v) & (v > 0)] * um)
    shown = np.concatenate(everything)
    top = max(float(shown.max()) if shown.size else 1.0, VC_LEVELS["VC-A"] * um) * 3.0
    bottom = min(float(shown.min()) if shown.size else 1.0, VC_LEVELS["VC-G"] * um) / 3.0
    lo_vc, hi_vc = BAND_LOWER[_band(VC_RANGE[0])], BAND_UPPER[_band(VC_RANGE[1])]  # the VC curves' bands
    for k, (ax, axis) in enumerate(zip(panels, AXES, strict=True)):
        for name, level in VC_LEVELS.items():
            ax.hlines(level * um, lo_vc, hi_vc, colors="0.6", linewidth=0.8)
            if k == 2:
                _label_line(ax, name, hi_vc, level * um, "0.4")
        for name, level in ISO_LEVELS.items():
            if level * um > top:
                continue
            ax.hlines(
                level * um,
                BAND_LOWER[_band(ISO_RANGE[0])],
                BAND_UPPER[_band(ISO_RANGE[1])],
                colors="0.75",
                linewidth=0.8,
                linestyles="dotted",
            )
            if k == 2:
                _label_line(ax, name, hi_vc, level * um, "0.5")
        if np.any(floor[k] > 0):
            ax.stairs(
                np.where(floor[k] > 0, floor[k] * um, np.nan),
                edges,
                color="black",
                linestyle="--",
                linewidth=1.2,
                label="floor",
                baseline=None,
            )
        for name, v in spectra["velocity"].items():
            v = np.asarray(v, dtype=float)[k]
            if not np.all(np.isfinite(v)):
                ax.plot([], [], label=f"{name}: tips over or is a mechanism")
                continue
            ax.stairs(np.where(v > 0, v * um, np.nan), edges, linewidth=1.8, label=name, baseline=None)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(edges[0] * 0.95, edges[-1] * 1.05)
        ax.set_ylim(bottom, top)
        ax.set_xlabel("one-third-octave band centre frequency (Hz)")
        ax.set_title(f"along {axis.upper()}" + ("" if np.any(floor[k] > 0) else " (floor still)"))
        ax.grid(True, which="both", alpha=0.25)
        ticks = [1, 2, 4, 8, 16, 31.5, 63]
        ax.set_xticks(ticks, [format_value(float(t)) for t in ticks])
    panels[0].set_ylabel(f"RMS velocity of {spectra['point']} per band (um/s)")
    panels[0].legend(loc="lower left", fontsize="small")
    worst = spectra.get("worst", {})
    notes = ", ".join(
        f"{t} {w[0] * um:.3g} um/s at {w[1]:.3g} Hz ({w[2]})" for t, w in worst.items() if np.isfinite(w[0])
    )
    fig.suptitle(
        (title or f"{spectra['point']}: floor-induced velocity against the VC curves")
        + (f"\nworst band: {notes}" if notes else "")
    )
    return figure_png(fig)


def _band(centre: float) -> int:
    """Number of the one-third-octave band of nominal ``centre`` (Hz)."""
    return int(round(10 * np.log10(centre)))
