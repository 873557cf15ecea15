"""The figure of a calibration: measured against simulated traces, one panel per channel (PNG bytes,
matplotlib's Agg canvas: no pyplot state, safe in threads).

Each panel draws the measurement (grey), the scene as given (dashed, aligned in time by the offset scan)
and the calibrated scene (solid), in the channel's own unit; acceleration channels as the fit saw them
(detrended and band-passed, measurement and simulation alike).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

DPI = 100


def calibration_png(traces: Mapping[str, Any], title: str = "", notes: Sequence[str] = ()) -> bytes:
    """Stacked panels of measured, before and after per channel.

    Args:
        traces: ``{"time": (N,) s, "channels": [{"name", "unit", "factor" (SI per unit), "measured",
            "before", "after" (N,) SI}]}`` (:attr:`isolab.studies.answers.calibration.Calibration.traces`).
        title: figure title.
        notes: lines printed under the title (fitted values, misfits).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t = np.asarray(traces["time"], dtype=float)
    channels = list(traces["channels"])
    n = max(len(channels), 1)
    fig = Figure(figsize=(10, 2.6 * n + 0.4 * len(notes) + 0.6), dpi=DPI, layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for ax, ch in zip(axes, channels, strict=False):
        f = float(ch.get("factor") or 1.0)
        ax.plot(t, np.asarray(ch["measured"]) / f, color="0.6", lw=2.5, alpha=0.7, label="measured")
        ax.plot(t, np.asarray(ch["before"]) / f, color="tab:blue", lw=1.0, ls="--", label="scene as given")
        ax.plot(t, np.asarray(ch["after"]) / f, color="tab:red", lw=0.9, label="calibrated")
        ax.set_ylabel(f"{ch['name']} ({ch['unit']})" if ch.get("unit") else ch["name"])
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("measurement time (s)")
    heading = "\n".join([title, *notes]) if notes else title
    if heading:
        fig.suptitle(heading, fontsize="medium")
    canvas = FigureCanvasAgg(fig)
    buf = io.BytesIO()
    canvas.print_png(buf)
    return buf.getvalue()


def calibration_notes(answer: Mapping[str, Any]) -> list[str]:
    """One line per fitted quantity (value +- sigma, or not determined) for a figure's heading."""
    lines = []
    for p in [*answer["parameters"], answer["time_offset"]]:
        if p["determined"]:
            lines.append(f"{p['path']} = {p['value']:.5g} +- {p['sigma']:.2g} {p['unit']}".rstrip())
        else:
            lines.append(f"{p['path']}: not determined by this measurement")
    return lines
