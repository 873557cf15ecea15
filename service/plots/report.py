"""The design report of a done study: one self-contained HTML file an engineer can send or print to PDF.

:func:`design_report` writes it from the study's answer
(:func:`isolab.studies.answers.study_answer.study_answer`), its design as written
(:func:`isolab.studies.authoring.authoring.design_summary`), its measured error and its figures (PNG
bytes, inlined as ``data:`` images): the scene, the question, the answer and the margins, the plots, the
model and its error estimate. It carries no script and no link to anything; every text it
shows is HTML-escaped. :func:`progress_png` draws an optimisation's best objective per generation.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from html import escape
from typing import Any

import numpy as np

from isolab.service.plots.studies import Series, case_png, figure_png, series, study_png
from isolab.studies.results.cases import CaseColumns
from isolab.studies.units import readable_unit

REPORT_POLICY = (
    "default-src 'none'; style-src 'unsafe-inline'; img-src data:; base-uri 'none'; form-action 'none'; "
    "frame-ancestors 'none'"
)
"""The report's Content-Security-Policy: its own style block and inline images, no script at all."""

STYLE = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; color: #1d2b3a; margin: 2em auto;
  max-width: 60em; padding: 0 1.5em; }
h1 { font-size: 1.6em; margin-bottom: 0.1em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccd;
  padding-bottom: 0.2em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; } th, td { border: 1px solid #ccd; padding: 0.25em
  0.6em; text-align: left; vertical-align: top; } th { background: #eef1f5; } td.num { text-align: right;
  font-variant-numeric: tabular-nums; white-space: nowrap; }
.pass { color: #1b6e2a; font-weight: 600; } .fail { color: #b3261e; font-weight: 600; }
.warn { background: #fff4d6; border-left: 4px solid #c77700; padding: 0.5em 0.8em; }
.ok { background: #e6f4ea; border-left: 4px solid #1b6e2a; padding: 0.5em 0.8em; }
.muted { color: #667; } figure { margin: 1em 0; } figure img { max-width: 100%; }
figcaption { color: #667; font-size: 0.9em; }
@media print { body { margin: 0; max-width: none; font-size: 11pt; } h2 { break-after: avoid; }
  table, figure { break-inside: avoid; } .warn, .ok, th { print-color-adjust: exact;
  -webkit-print-color-adjust: exact; } }
"""


def quantity(value: Any, unit: str) -> str:
    """``value`` (SI) with a unit read easily at its magnitude (``5.67 mm``, ``12.4 um/s``); a
    dimensionless value as it is; "–" for none."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    if isinstance(value, str | bool):
        return str(value)
    shown, one = readable_unit(unit, np.array([float(value)]))
    shown = "" if shown in ("", "1") else shown
    return f"{float(value) / one:.4g} {shown}".rstrip()


def percent(fraction: float | None) -> str:
    """A fraction as a signed percentage (``+17 %``, ``-126 %``); "–" for none."""
    if fraction is None or not math.isfinite(fraction):
        return "–"
    return f"{100 * fraction:+.1f} %"


def progress_png(progress: Sequence[Mapping[str, Any]], label: str, unit: str) -> bytes:
    """An optimisation's best feasible objective of each generation and the best so far (SI ``unit``,
    drawn in a readable one), as PNG bytes."""
    gens = np.array([p["generation"] for p in progress], dtype=float)
    best = np.array([np.nan if p["best"] is None else p["best"] for p in progress], dtype=float)
    so_far = np.array(
        [np.nan if p["best_so_far"] is None else p["best_so_far"] for p in progress], dtype=float
    )
    shown, one = readable_unit(unit, best[np.isfinite(best)] if np.isfinite(best).any() else np.array([1.0]))
    from matplotlib.figure import Figure  # on first use: the service starts sooner without it

    fig = Figure(figsize=(7.5, 3.4), dpi=100)
    ax = fig.add_subplot()
    ax.plot(gens, best / one, "o", color="#1f77b4", label="best feasible case of the generation")
    ax.step(gens, so_far / one, where="post", color="#d62728", label="best so far")
    ax.set_xlabel("generation")
    ax.set_ylabel(f"{label} ({shown})" if shown not in ("", "1") else label)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return figure_png(fig)


def _table(head: Sequence[str], rows: Sequence[Sequence[str]], numeric: Sequence[int] = ()) -> str:
    """A table of already escaped cells."""
    th = "".join(f"<th>{h}</th>" for h in head)
    body = "".join(
        "<tr>"
        + "".join(f"<td{' class=num' if i in numeric else ''}>{c}</td>" for i, c in enumerate(r))
        + "</tr>"
        for r in rows
    )
    return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def _verdict(margin: float | None) -> str:
    if margin is None or not math.isfinite(margin):
        return '<span class="fail">not judged</span>'
    return '<span class="pass">pass</span>' if margin >= 0 else '<span class="fail">fail</span>'


def _limit(criterion: Mapping[str, Any]) -> str:
    if criterion["name"] == "isolators_no_liftoff":
        return "keeps part of its preload"
    return escape(quantity(criterion["limit"], criterion["unit"]))


def _value(criterion: Mapping[str, Any], value: float | None) -> str:
    if criterion["name"] == "isolators_no_liftoff":
        return escape(percent(value).lstrip("+") + " of preload kept") if value is not None else "–"
    return escape(quantity(value, criterion["unit"]))


def margins_table(criteria: Sequence[Mapping[str, Any]], case: Mapping[str, Any]) -> str:
    """One case's criteria: what each judges, its limit, the value, the margin in % and pass or fail."""
    rows = [
        [
            escape(c["description"]),
            _limit(c),
            _value(c, case["values"].get(c["name"])),
            escape(percent(case["margins"].get(c["name"]))),
            _verdict(case["margins"].get(c["name"])),
        ]
        for c in criteria
    ]
    return _table(["criterion", "limit", "value", "margin", ""], rows, numeric=(2, 3))


def _scene(scene: Mapping[str, Any]) -> str:
    facts = []
    if scene.get("mass") is not None:
        how = ""
        block = scene.get("block")
        if scene.get("mass_from") == "block" and block:
            size = " x ".join(f"{float(v):.4g}" for v in block["size"])
            how = f" (a block of {size} m at {float(block['density']):.4g} kg/m³)"
        facts.append(f"Base mass {float(scene['mass']):,.0f} kg{how}.")
    if scene.get("isolator_type"):
        facts.append(f"{scene.get('n_mounts', '?')} mounts, type {scene['isolator_type']}.")
    if scene.get("points"):
        facts.append("Points of interest: " + ", ".join(str(p) for p in scene["points"]) + ".")
    out = "<p>" + escape(" ".join(facts)) + "</p>"
    stages = scene.get("stages") or []
    if stages:
        rows = [
            [
                escape(str(s.get("name"))),
                escape(quantity(s.get("mass"), "kg")),
                escape(quantity(s.get("travel"), "m")),
                escape(", ".join(f"{float(v):g}" for v in s.get("axis") or [])),
                escape(str(s.get("profile") or "–")),
            ]
            for s in stages
        ]
        out += _table(["stage", "mass", "travel", "axis", "profile"], rows, numeric=(1, 2))
    return out


def _question(answer: Mapping[str, Any], design: Mapping[str, Any] | None) -> str:
    q = answer["question"]
    out = f"<p>{escape(str(q.get('design') or '–'))} design, {int(answer['n_cases'])} cases.</p>"
    params = (design or {}).get("parameters") or []
    if params:
        rows = []
        for p in params:
            if p.get("values"):
                written = ", ".join(str(v) for v in p["values"])
            elif p.get("range"):
                written = f"{p['range'].get('start')} … {p['range'].get('stop')}"
            else:
                written = "–"
            rows.append([escape(str(p["name"])), escape(str(p.get("path", ""))), escape(written)])
        out += _table(["varied parameter", "sets", "values as written"], rows)
    if q.get("objectives"):
        out += "<p>Objective: " + escape(", ".join(q["objectives"]))
        out += (
            (". Constraints: " + escape(", ".join(q.get("constraints") or [])))
            if q.get("constraints")
            else ""
        )
        out += ".</p>"
    if q.get("criteria"):
        rows = [[escape(c["description"]), _limit(c)] for c in q["criteria"]]
        out += "<p>Criteria:</p>" + _table(["criterion", "limit"], rows)
    return out


def _answer(answer: Mapping[str, Any], design: Mapping[str, Any] | None) -> str:
    crit = answer["question"].get("criteria") or []
    opt = answer.get("optimisation")
    out = ""
    if opt is not None:
        obj = opt["objective"]
        if opt.get("best_case") is None:
            out += (
                '<p class="warn">No feasible case: no design the optimiser tried meets its constraints.</p>'
            )
        else:
            best = opt["best_objectives"].get(obj["quantity"])
            out += (
                f'<p class="ok">Best design: case {int(opt["best_case"])} (generation '
                f"{int(opt['best_generation'])}), {escape(obj['long_name'])} = "
                f"{escape(quantity(best, obj['unit']))}.</p>"
            )
            written = {p["name"]: p for p in (design or {}).get("parameters") or []}
            rows = []
            for p in opt["parameters"]:
                unit = p["unit"] or "1"
                flag = (
                    f"at the {p['at_limit']} end of its range: the optimum may lie beyond"
                    if p["at_limit"]
                    else ""
                )
                plateau = p.get("plateau")
                rows.append(
                    [
                        escape(str(p["name"])),
                        escape(_in_written(p["best"], unit, written.get(p["name"]))),
                        escape(
                            f"{_in_written(p['low'], unit, written.get(p['name']))} … "
                            f"{_in_written(p['high'], unit, written.get(p['name']))}"
                        ),
                        escape(
                            f"{_in_written(plateau[0], unit, written.get(p['name']))} … "
                            f"{_in_written(plateau[1], unit, written.get(p['name']))}"
                            if plateau
                            else "–"
                        ),
                        f'<span class="fail">{escape(flag)}</span>' if flag else "",
                    ]
                )
            out += _table(["parameter", "best", "range", "plateau", "range limit"], rows, numeric=(1,))
            out += (
                f"<p class=muted>{escape(str(opt['algorithm']))}: {int(opt['generations'])} generations, "
                f"{int(opt['n_cases'])} cases, {int(opt['n_feasible'])} feasible; the plateau holds "
                f"{int(opt.get('n_plateau', 0))} feasible cases within "
                f"{100 * float(opt.get('plateau', 0)):.3g} % "
                f"of the best objective; stopped: {escape(str(opt.get('stopped', '–')))}.</p>"
            )
            if opt.get("best_margins"):
                out += "<p>Margins of the best design:</p>" + margins_table(crit, opt["best_margins"])
        return out
    c = answer.get("criteria")
    if c is None:
        return "<p class=muted>The study carries no criteria: its answer is its case table and plots.</p>"
    n = int(answer["n_cases"])
    if c["n_meeting"]:
        out += f'<p class="ok">{int(c["n_meeting"])} of {n} cases meet every criterion.</p>'
    else:
        out += f'<p class="warn">No case meets every criterion ({n} cases).</p>'
    if c.get("best_case"):
        b = c["best_case"]
        out += f"<p>Largest smallest margin: case {int(b['case'])} ({escape(b['label'])}).</p>"
    cases = c.get("cases") or ([c["best_case"]] if c.get("best_case") else [])
    for case in cases:
        out += f"<h3>Case {int(case['case'])}: {escape(case['label'])}</h3>" + margins_table(crit, case)
    return out


def _in_written(value: float | None, unit: str, written: Mapping[str, Any] | None) -> str:
    """A parameter value in the unit its author wrote (``display_unit``, ``display_scale``)."""
    if value is None:
        return "–"
    if written and written.get("display_scale"):
        u = written.get("display_unit") or ""
        return f"{float(value) / float(written['display_scale']):.4g} {'' if u == '1' else u}".rstrip()
    return quantity(value, unit)


def _model(answer: Mapping[str, Any], error: Mapping[str, Any] | None) -> str:
    m = answer["model"]
    dt = f"{1e3 * m['dt']:.4g} ms" if m.get("dt") else "–"
    out = (
        f"<p>Fidelity {escape(str(m.get('fidelity') or '–'))}, "
        f"integrator {escape(str(m.get('integrator') or '–'))},"
        f" time step {escape(dt)} ({escape(str(m.get('reason') or '–'))}).</p>"
    )
    outputs = (error or {}).get("outputs") or {}
    if not outputs:
        return out + "<p class=muted>This study carries no error estimate.</p>"
    rows = []
    for name, o in outputs.items():
        v = o.get("value")
        shown = (
            "–" if v is None else (f"{100 * v:.3g} %" if o.get("units") == "1" else quantity(v, o["units"]))
        )
        worst = o.get("worst_case")
        rows.append([escape(str(name)), escape(str(o.get("meaning", ""))), escape(shown), escape(str(worst))])
    out += _table(["output", "what", "largest error", "worst case"], rows, numeric=(2,))
    cases = (error or {}).get("cases") or []
    out += (
        f"<p class=muted>Measured on {len(cases)} sampled cases against the reference level "
        f"({escape(str((error or {}).get('method') or '–'))}).</p>"
    )
    return out


def design_report(
    answer: Mapping[str, Any],
    design: Mapping[str, Any] | None,
    error: Mapping[str, Any] | None,
    figures: Sequence[tuple[str, bytes]] = (),
    now: datetime | None = None,
) -> str:
    """The report as HTML text (see the module): ``figures`` are (caption, PNG bytes)."""
    when = (now or datetime.now(UTC)).strftime("%Y-%m-%d %H:%M UTC")
    name = escape(str(answer["name"]))
    figs = "".join(
        f'<figure><img alt="{escape(caption)}" src="data:image/png;base64,{base64.b64encode(png).decode()}">'
        f"<figcaption>{escape(caption)}</figcaption></figure>"
        for caption, png in figures
    )
    return (
        '<!doctype html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>isolab design report – {name}</title><style>{STYLE}</style></head><body>"
        f"<h1>Design report: {name}</h1>"
        f"<p>{escape(str(answer.get('description') or ''))}</p>"
        f"<p class=muted>Study {escape(str(answer['study_id']))}, "
        f"run {escape(str(answer.get('created') or '–'))};"
        f" report written {escape(when)} by isolab.</p>"
        f"<h2>The scene</h2>{_scene(answer['scene'])}"
        f"<h2>The question</h2>{_question(answer, design)}"
        f"<h2>The answer and its margins</h2>{_answer(answer, design)}"
        + (f"<h2>Plots</h2>{figs}" if figs else "")
        + f"<h2>The model and its error estimate</h2>{_model(answer, error)}"
        + "</body></html>\n"
    )


def report_figures(
    answer: Mapping[str, Any], table: CaseColumns, history: Any = None, history_title: str = ""
) -> list[tuple[str, bytes]]:
    """The report's figures, (caption, PNG): an optimisation's progress, or each criterion's margin (else
    the c.g.'s peak Y displacement) against the first varied parameter; and the time response ``history``
    (:class:`isolab.studies.answers.history.CaseHistory`) of the case the answer points at."""
    figures: list[tuple[str, bytes]] = []
    opt = answer.get("optimisation")
    if opt is not None and opt.get("progress"):
        obj = opt["objective"]
        figures.append(
            (
                f"Best {obj['long_name']} per generation",
                progress_png(opt["progress"], obj["quantity"], obj["unit"]),
            )
        )
    elif table.parameters:
        x = table.parameters[0]
        group = "isolator_type" if "isolator_type" in table.parameters and x != "isolator_type" else None
        crit = answer["question"].get("criteria") or []
        ys = [f"margin_{c['name']}" for c in crit if f"margin_{c['name']}" in table.data][:4]
        if not ys and "peak_displacement_y" in table.data:
            ys = ["peak_displacement_y"]
        for y in ys:
            png = study_png(
                y=series(table, y),
                x=series(table, x),
                group=Series(group, table.data[group], "") if group else None,
                sampled=table.design_kind == "sampled",
                reduce="min" if y.startswith(("margin_", "min_")) else "max",
                title=str(answer["name"]),
            )
            figures.append((f"{table.long_names.get(y, y)} against {x}", png))
    if history is not None:
        png = case_png(
            history.time,
            history.displacement,
            history.rotation,
            history.isolator_force,
            history.isolator_names,
            history_title,
        )
        figures.append((history_title, png))
    return figures


def report_case(answer: Mapping[str, Any]) -> int:
    """The case whose time response the report draws: the optimum, else the case of the largest smallest
    criterion margin, else the first."""
    opt = answer.get("optimisation")
    if opt is not None and opt.get("best_case") is not None:
        return int(opt["best_case"])
    crit = answer.get("criteria")
    if crit and crit.get("best_case"):
        return int(crit["best_case"]["case"])
    return 0
