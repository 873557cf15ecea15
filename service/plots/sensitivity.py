"""The figure of a sensitivity analysis as PNG bytes (matplotlib's Agg canvas, as :mod:`service.plots`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from isolab.service.plots.studies import figure_png, new_figure

_COLOURS = {"S1": "#1f77b4", "ST": "#d62728", "delta": "#2ca02c"}
_LABELS = {"S1": "S1 (first order)", "ST": "ST (total order)", "delta": "delta (Borgonovo)"}


def _parameter_label(name: str, long_name: str, unit: str) -> str:
    """``stage_y_mass`` with the path it sets and its unit, on two lines."""
    sets = long_name.split("(sets ", 1)[1].rstrip(")") if "(sets " in long_name else ""
    second = ", ".join(x for x in (sets, unit) if x)
    return f"{name}\n({second})" if second else name


def sensitivity_png(result: dict[str, Any], title: str = "") -> bytes:
    """Grouped horizontal bars of each index per parameter with its 95 % confidence interval as error
    bars; ``result`` is :meth:`isolab.studies.answers.sensitivity.SensitivityResult.to_dict`."""
    names = list(result["parameters"])
    kinds = list(result["indices"])
    n, k = len(names), len(kinds)
    fig = new_figure(8, 1.2 + 0.45 * n * k + 0.6)
    ax = fig.add_subplot()
    height = 0.8 / max(k, 1)
    pos = np.arange(n)[::-1].astype(float)
    for j, kind in enumerate(kinds):
        vals = np.array([np.nan if v is None else v for v in result["indices"][kind]], dtype=float)
        conf = np.array(
            [np.nan if v is None else v for v in result["conf"].get(kind, [None] * n)], dtype=float
        )
        y = pos + (k - 1 - 2 * j) * height / 2
        ax.barh(
            y,
            np.nan_to_num(vals),
            height=height * 0.9,
            xerr=np.nan_to_num(conf),
            color=_COLOURS.get(kind, f"C{j}"),
            capsize=3,
            label=_LABELS.get(kind, kind),
        )
    ax.set_yticks(pos)
    ax.set_yticklabels(
        [
            _parameter_label(nm, ln, u)
            for nm, ln, u in zip(
                names, result["parameter_long_names"], result["parameter_units"], strict=True
            )
        ],
        fontsize=8,
    )
    ax.axvline(0.0, color="0.3", linewidth=0.8)
    ax.set_xlim(min(-0.05, ax.get_xlim()[0]), max(1.0, ax.get_xlim()[1]))
    unit = f" ({result['unit']})" if result.get("unit") else ""
    ax.set_xlabel(f"index of {result['output']}: {result['long_name']}{unit}", fontsize=8, wrap=True)
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    head = f"{title}: " if title else ""
    method = "Sobol' (Saltelli)" if result["method"] == "sobol" else "delta (given data)"
    ax.set_title(
        f"{head}sensitivity of {result['output']}\n{method}, {result['n_cases']} of {result['n_total']} "
        f"cases, bars: {int(round(100 * result.get('conf_level', 0.95)))} % CI",
        fontsize=9,
    )
    return figure_png(fig)
