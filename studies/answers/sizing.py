"""Sizing the isolators from a catalogue: which product, how many per mount position, at what pressure.

For each product of the catalogue the sizing builds one design: the product at every mount position, with
the fewest isolators side by side (of the scene's ``per_corner`` choices) that carry the position's static
load inside the product's rated range with the stated margin. A design whose loads fit is a candidate;
candidates run through the engine cheapest first (a few at a time, one batch each), and the first that meets
every criterion of the scene, survives its peak loads within the product's maximum load and uses no more
than the product's stroke is the answer. Every cheaper product is answered with why it fails: the load out
of its rated range at a named mount, or the criterion it misses and by how much.

With figures given at rated load (frequency and damping ratio), a position of ``n`` isolators has ``n``
times the stiffness and damping of one isolator carrying ``1/n`` of the load: the same frequency and
damping. The count changes the load per isolator, the pressure and the cost, not the dynamics.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from isolab.engine import simulate
from isolab.studies.inputs.catalogues import (
    DEFAULT_LOAD_MARGIN,
    MAX_PER_CORNER,
    Catalogue,
    LoadMargin,
    PerCornerCounts,
    Product,
    load_catalogue,
    scene_catalogue,
)
from isolab.studies.inputs.definitions import DefinitionError, check_definition, detail, validation_details
from isolab.studies.inputs.isolators import mount_labels
from isolab.studies.inputs.scenes import isolator_loads
from isolab.studies.inputs.schema.scene_paths import ISOLATOR_MODEL
from isolab.studies.inputs.study import Study, study_labels, validate_scene
from isolab.studies.questions.criteria import add_criteria
from isolab.studies.results.dataset import to_dataset
from isolab.studies.run.accuracy import resolved_study

"""The static load of each isolator may change by this fraction either way and stay in its rated range."""
MAX_SIZING_CASES = 64
"""Most candidate designs one sizing simulates (``max_cases``)."""
CHUNK = 8
"""Candidate designs simulated in one engine batch, cheapest first."""
ISOLATOR_CHOICE_KEYS = ("model", "preset", "f_vertical", "f_horizontal", "zeta", "skyhook", "k", "c")
"""What a sizing replaces in the scene's isolators (group and listed mounts): the product decides them."""
GROUP_ONLY_KEYS = ("tuning", "feedforward", "catalogue", "per_corner")


class SizingRequest(BaseModel):
    """One scene sized from a catalogue: the body of ``POST /sizings`` (strict: ``margin: false`` is no
    number)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    scene: dict[str, Any] = Field(description="inline scene (as in a study's scene block), with its criteria")
    catalogue: dict[str, Any] | str | None = Field(
        None,
        description="the catalogue inline (as in a catalogue file: name, currency, products), or a shipped "
        "one by name (default: representative)",
    )
    margin: LoadMargin = Field(
        DEFAULT_LOAD_MARGIN,
        description="load margin: each isolator's static load may change by this fraction either way and "
        "stay in its rated range, 1",
    )
    per_corner: PerCornerCounts | None = Field(
        None,
        description="how many isolators side by side a mount position may take (default: the scene's "
        "isolators.per_corner, else [1])",
    )
    simulation: dict[str, Any] | None = Field(
        None, description="overrides of the scene's simulation block (fidelity, integrator, dt, duration...)"
    )
    max_cases: int = Field(
        32,
        ge=1,
        le=MAX_SIZING_CASES,
        description=f"most candidate designs simulated (at most {MAX_SIZING_CASES})",
    )


class SizingAnswer(BaseModel):
    """The answer of a sizing (SI; ``units`` names each figure's unit, ``cost`` in ``currency``)."""

    feasible: bool = Field(description="whether a product carries every load and meets every criterion")
    summary: str = Field(description="the answer in words: the product, how many, the cost, or why none fits")
    catalogue: str
    currency: str
    margin: float = Field(description="the load margin asked for, 1")
    per_corner: list[int] = Field(description="the counts a mount position could take")
    criteria: list[str] = Field(description="the scene's criteria the designs were judged by")
    design: dict[str, Any] | None = Field(description="the chosen product, its count, cost and margins")
    mounts: list[dict[str, Any]] = Field(
        description="per mount: static load, product, count, load per isolator, load margin, pressure, "
        "peak deflection, stroke used, and why each cheaper product fails (cheaper)"
    )
    candidates: list[dict[str, Any]] = Field(description="every product: counts, cost, verdict and reason")
    cases_run: int = Field(description="candidate designs simulated")
    units: dict[str, str]
    scene: dict[str, Any] | None = Field(description="the scene standing on the chosen product (model:)")


def load_margin(load: float, product: Product) -> float:
    """The fraction by which a static load per isolator (N) may change either way and stay in the
    product's rated range: ``min(max/F - 1, 1 - min/F)`` (negative: outside the range), 1."""
    if not load > 0:
        return -math.inf
    return min(product.rated_load.max / load - 1.0, 1.0 - product.rated_load.min / load)


@dataclass
class Fit:
    """A product at one mount position: the count, the load per isolator and its margin; ``reason`` says
    why it does not fit (None: it fits)."""

    count: int | None
    load: float
    margin: float
    pressure: float | None
    reason: str | None


def _kn(x: float) -> str:
    return f"{x / 1e3:.3g} kN"


def fit(product: Product, load: float, margin: float, per_corner: list[int]) -> Fit:
    """The fewest isolators of ``product`` (of ``per_corner``) that carry ``load`` (N) with ``margin``."""
    for n in sorted(per_corner):
        share = load / n
        m = load_margin(share, product)
        if m < margin:
            continue
        p = product.pressure(share)
        if p is not None and product.max_pressure is not None and p > product.max_pressure:
            continue
        return Fit(n, share, m, p, None)
    r = product.rated_load
    counts = " or ".join(str(n) for n in sorted(per_corner))
    shares = ", ".join(_kn(load / n) for n in sorted(per_corner))
    reason = (
        f"load out of range: {_kn(load)} on {counts} isolator(s) is {shares} each, outside the rated "
        f"{_kn(r.min)} to {_kn(r.max)} with a {margin:.0%} margin"
    )
    if product.max_pressure is not None and product.effective_area is not None:
        reason += f" (or above {product.max_pressure / 1e5:.3g} bar)"
    return Fit(None, load, max(load_margin(load / n, product) for n in per_corner), None, reason)


@dataclass
class Candidate:
    """One product at every mount position: its fits, cost, and (once simulated) its verdict."""

    product: Product
    fits: list[Fit]
    cost: float | None = None
    verdict: str = "not simulated"
    reason: str | None = None
    margins: dict[str, float | None] = field(default_factory=dict)
    peak_deflection: list[float] = field(default_factory=list)
    peak_load: list[float] = field(default_factory=list)

    @property
    def feasible(self) -> bool:
        return all(f.count is not None for f in self.fits)

    @property
    def count(self) -> int:
        return sum(f.count or 0 for f in self.fits)

    @property
    def least_cost(self) -> float:
        """Its cost, or for a design whose loads do not fit what one isolator a position would cost (inf
        without a price): what it would have cost at best."""
        if self.cost is not None:
            return self.cost
        if self.product.price is None:
            return math.inf
        return self.product.price * sum(f.count or 1 for f in self.fits)


def strip_isolator_choice(scene: dict[str, Any]) -> dict[str, Any]:
    """``scene`` with what the product decides removed from its isolators (group and listed mounts)."""
    s = copy.deepcopy(scene)
    iso = s.get("isolators")
    if not isinstance(iso, dict):
        return s
    for key in ISOLATOR_CHOICE_KEYS + GROUP_ONLY_KEYS:
        iso.pop(key, None)
    for mt in iso.get("list") or []:
        if isinstance(mt, dict):
            for key in ISOLATOR_CHOICE_KEYS + ("feedforward",):
                mt.pop(key, None)
    return s


def _cost(product: Product, count: int) -> float | None:
    return None if product.price is None else product.price * count


def _candidate_study(base: dict[str, Any], batch: list[Candidate], simulation: Any) -> Study:
    """The list study of ``batch``: one case per candidate, standing on its product (``isolators.model``,
    the catalogue inline in ``base``)."""
    ids = [c.product.id for c in batch]
    body: dict[str, Any] = {
        "name": "sizing",
        "scene": base,
        "parameters": [{"path": ISOLATOR_MODEL, "values": ids}],
        "design": {"type": "list", "cases": [{"product": pid} for pid in ids]},
    }
    if simulation is not None:
        body["simulation"] = simulation
    return resolved_study(check_definition(body, prefix=["body"]))


def _judge(batch: list[Candidate], study: Study) -> list[str]:
    """Run ``batch`` through the engine and set each candidate's verdict; the criteria's names."""
    sim = study.simulation
    fidelity, integrator, dt = sim.engine_choice()
    result = simulate(
        study.batch(np.arange(study.n_cases)), fidelity=fidelity, integrator=integrator, dt=dt,
        auto_step=sim.auto_step,
    )  # fmt: skip
    iso, pts = study_labels(study)
    ds = add_criteria(to_dataset(result, study.design(), isolator_names=iso, point_names=pts), study.criteria)
    names = study.criteria.names() if study.criteria is not None and "criterion" in ds.dims else []
    margins = (
        ds["criterion_margin"].transpose(..., "criterion").values.reshape(len(batch), -1)
        if names
        else np.zeros((len(batch), 0))
    )
    deflection = np.abs(np.asarray(result.peak_isolator_deflection))[..., 2]
    peak = np.asarray(result.max_isolator_load)
    for i, c in enumerate(batch):
        c.margins = {n: float(m) if np.isfinite(m) else None for n, m in zip(names, margins[i], strict=True)}
        c.peak_deflection = [float(x) for x in deflection[i]]
        c.peak_load = [float(x) for x in peak[i]]
        problems = []
        if int(result.status[i]) != 0:
            problems.append(f"its case did not end ok (status {int(result.status[i])})")
        missed = [f"{n} missed by {-m:.0%}" for n, m in c.margins.items() if m is not None and m < 0]
        problems += missed
        p = c.product
        for j, f in enumerate(c.fits):
            n = f.count or 1
            if p.stroke is not None and c.peak_deflection[j] > p.stroke:
                problems.append(
                    f"stroke exceeded at mount_{j}: {c.peak_deflection[j] * 1e3:.3g} mm of "
                    f"{p.stroke * 1e3:.3g} mm"
                )
            if p.max_load is not None and c.peak_load[j] / n > p.max_load:
                problems.append(
                    f"peak load at mount_{j} {_kn(c.peak_load[j] / n)} per isolator above its maximum "
                    f"{_kn(p.max_load)}"
                )
        c.verdict = "fails" if problems else "passes"
        c.reason = "; ".join(problems) if problems else None
    return names


def _scene_error(err: ValidationError | ValueError) -> DefinitionError:
    if isinstance(err, ValidationError):
        return DefinitionError(validation_details(err, ["body", "scene"]))
    return DefinitionError([detail(["body", "scene"], str(err))])


def requested_catalogue(catalogue: Catalogue | str | dict[str, Any] | None) -> Catalogue:
    """The catalogue a request names: inline data, a :class:`Catalogue`, a shipped one by name, or (None)
    the default. A name is a shipped catalogue's, never a file: the caller reads files (the CLI does).

    Raises:
        DefinitionError: naming the field under ``body.catalogue`` (``products.2.rated_load.max``).
    """
    try:
        if isinstance(catalogue, Catalogue | dict):
            return load_catalogue(catalogue)
        return scene_catalogue(catalogue, "catalogue")
    except ValidationError as err:
        raise DefinitionError(validation_details(err, ["body", "catalogue"])) from None
    except ValueError as err:
        raise DefinitionError([detail(["body", "catalogue"], str(err))]) from None


def scene_loads(
    scene: dict[str, Any], per_corner: list[int] | None = None
) -> tuple[dict[str, Any], list[int], np.ndarray]:
    """What a catalogue is judged against: the scene (as data) with the isolator choice taken out
    (:func:`strip_isolator_choice`), the counts a mount position may take (``per_corner``, else the
    scene's ``isolators.per_corner``, else [1]) and the static load of each mount position, N.

    Raises:
        DefinitionError: naming ``body.scene...`` or ``body.per_corner``.
    """
    if not isinstance(scene, dict):
        raise DefinitionError([detail(["body", "scene"], "expected the scene as a mapping")])
    given = scene.get("isolators")
    counts = sorted(set(per_corner or (given.get("per_corner") if isinstance(given, dict) else None) or [1]))
    if any(not 1 <= n <= MAX_PER_CORNER for n in counts):
        raise DefinitionError(
            [detail(["body", "per_corner"], f"each count must lie between 1 and {MAX_PER_CORNER}: {counts}")]
        )
    base = strip_isolator_choice(scene)
    try:
        loads = isolator_loads(validate_scene(base))
    except (ValidationError, ValueError) as err:
        raise _scene_error(err) from None
    return base, counts, loads


def product_candidates(
    catalogue: Catalogue, loads: np.ndarray, margin: float, counts: list[int]
) -> list[Candidate]:
    """Each product of ``catalogue`` at every mount position (static ``loads``, N): the fewest isolators of
    ``counts`` carrying each load inside the rated range with ``margin`` (:func:`fit`), the cost, and for a
    product whose loads do not fit, the verdict ``fails`` with the reason per mount. In catalogue order."""
    labels = mount_labels(len(loads))
    candidates = []
    for p in catalogue.products:
        fits = [fit(p, float(w), margin, counts) for w in loads]
        c = Candidate(p, fits)
        c.cost = _cost(p, c.count) if c.feasible else None
        if not c.feasible:
            c.verdict = "fails"
            c.reason = "; ".join(f"{labels[j]}: {f.reason}" for j, f in enumerate(fits) if f.reason)
        candidates.append(c)
    return candidates


def size(
    scene: dict[str, Any],
    catalogue: Catalogue | str | dict[str, Any] | None = None,
    *,
    margin: float = DEFAULT_LOAD_MARGIN,
    per_corner: list[int] | None = None,
    simulation: Any = None,
    max_cases: int = 32,
) -> dict[str, Any]:
    """Size ``scene``'s isolators from ``catalogue`` (default the shipped one): the cheapest product (and
    count per position) whose static loads fit with ``margin`` and whose design meets the scene's criteria.

    Answers ``feasible``, the chosen ``design`` (product, count, cost), per mount the ``static_load`` (N),
    ``count``, ``load_per_isolator`` (N), ``load_margin`` (1), ``pressure`` (Pa, gauge; air springs with an
    effective area), ``peak_deflection`` and ``stroke_used`` (1) and why each cheaper product fails
    (``cheaper``), every ``candidate`` with its verdict, the sized ``scene`` (``model:``) and a ``summary``.

    Raises:
        DefinitionError: bad input, naming the field (``body.scene...``, ``body.catalogue...``).
    """
    cat = requested_catalogue(catalogue)
    base, counts, loads = scene_loads(scene, per_corner)
    labels = mount_labels(len(loads))
    order = sorted(
        product_candidates(cat, loads, margin, counts),
        key=lambda c: (not c.feasible, math.inf if c.cost is None else c.cost, c.product.id),
    )
    runnable = [c for c in order if c.feasible]
    base.setdefault("isolators", {})["catalogue"] = cat.model_dump(mode="json", exclude_none=True)
    chosen: Candidate | None = None
    criteria: list[str] = []
    run = 0
    while runnable and chosen is None and run < max_cases:
        batch = runnable[: min(CHUNK, max_cases - run)]
        runnable = runnable[len(batch) :]
        try:
            criteria = _judge(batch, _candidate_study(base, batch, simulation))
        except ValueError as err:
            raise _scene_error(err) from None
        run += len(batch)
        chosen = next((c for c in batch if c.verdict == "passes"), None)
    for c in runnable:
        c.reason = f"not simulated: the sizing stops at max_cases ({max_cases})" if chosen is None else None
    return _answer(cat, scene, loads, labels, order, chosen, criteria, margin, counts, run)


def _answer(
    cat: Catalogue,
    scene: dict[str, Any],
    loads: np.ndarray,
    labels: list[str],
    order: list[Candidate],
    chosen: Candidate | None,
    criteria: list[str],
    margin: float,
    counts: list[int],
    run: int,
) -> dict[str, Any]:
    """The sizing's answer as data (SI), the chosen design's per-mount figures and every candidate."""
    if chosen is None:
        cheaper = order
    else:  # every product that would have cost less: a feasible one before it, any with a lower least cost
        cheaper = [
            c
            for c in order
            if c is not chosen and (c.least_cost if c.cost is None else c.cost) < chosen.least_cost
        ]
    mounts = []
    for j, (label, w) in enumerate(zip(labels, loads, strict=True)):
        row: dict[str, Any] = {"mount": label, "static_load": float(w)}
        if chosen is not None:
            f = chosen.fits[j]
            p = chosen.product
            row.update(
                product=p.id,
                count=f.count,
                load_per_isolator=f.load,
                load_margin=f.margin,
                pressure=f.pressure,
                peak_deflection=chosen.peak_deflection[j] if chosen.peak_deflection else None,
                stroke=p.stroke,
                stroke_used=(chosen.peak_deflection[j] / p.stroke)
                if p.stroke is not None and chosen.peak_deflection
                else None,
            )
        else:
            fitting = [c.product.id for c in order if c.fits[j].count is not None]
            row["reason"] = (
                f"{', '.join(fitting)} carry its load with a {margin:.0%} margin"
                if fitting
                else f"no product of the catalogue carries {_kn(float(w))} with a {margin:.0%} margin "
                f"(on {' or '.join(map(str, counts))} isolator(s))"
            )
        row["cheaper"] = [
            {"product": c.product.id, "reason": c.fits[j].reason or c.reason or c.verdict} for c in cheaper
        ]
        mounts.append(row)
    design = None
    if chosen is not None:
        p = chosen.product
        design = {
            "product": p.id,
            "label": p.label(),
            "type": p.type,
            "isolators": chosen.count,
            "unit_price": p.price,
            "cost": chosen.cost,
            "lead_time": p.lead_time,
            "margins": chosen.margins,
            "source": p.source,
        }
        summary = (
            f"{chosen.count} x {p.label()}"
            + (f" for {chosen.cost:,.0f} {cat.currency}" if chosen.cost is not None else " (no price given)")
            + (f": the cheapest product meeting {', '.join(criteria)}" if criteria else ": no criteria, "
               "chosen on load and cost alone")
            + f" with every static load inside its rated range by at least {margin:.0%}"
        )  # fmt: skip
    else:
        reasons = "; ".join(f"{c.product.id}: {c.reason}" for c in order if c.reason)
        summary = f"no feasible product in catalogue {cat.name!r}: {reasons or 'no product was simulated'}"
    return {
        "feasible": chosen is not None,
        "summary": summary,
        "catalogue": cat.name,
        "currency": cat.currency,
        "margin": margin,
        "per_corner": counts,
        "criteria": criteria,
        "design": design,
        "mounts": mounts,
        "candidates": [
            {
                "product": c.product.id,
                "type": c.product.type,
                "counts": [f.count for f in c.fits],
                "cost": c.cost,
                "verdict": "chosen" if c is chosen else c.verdict,
                "reason": c.reason,
                "margins": c.margins,
            }
            for c in order
        ],
        "cases_run": run,
        "units": {
            "static_load": "N",
            "load_per_isolator": "N",
            "load_margin": "1",
            "pressure": "Pa",
            "peak_deflection": "m",
            "stroke": "m",
            "stroke_used": "1",
            "lead_time": "s",
            "cost": cat.currency,
        },
        "scene": sized_scene(scene, chosen.product, cat) if chosen is not None else None,
    }


def sized_scene(scene: dict[str, Any], product: Product, catalogue: Catalogue) -> dict[str, Any]:
    """``scene`` standing on ``product`` (``isolators.model``), the catalogue carrying that product inline."""
    s = strip_isolator_choice(scene)
    iso = s.setdefault("isolators", {})
    iso["model"] = product.id
    iso["catalogue"] = {
        "name": catalogue.name,
        "currency": catalogue.currency,
        "products": [product.model_dump(mode="json", exclude_none=True)],
    }
    return s
