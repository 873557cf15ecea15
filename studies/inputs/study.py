"""A study: a base scene, the parameters it varies and the design that picks their values.

``load_study`` reads a YAML or JSON study file (or a dict), ``Study.design()`` lists the cases and
``Study.batch(indices)`` turns any cases into the engine's :class:`~engine.scene.SceneBatch`.

Batch building is vectorised: cases are grouped by their categorical values (isolator types), the scene
of each group is validated once, and the continuous values go into the arrays directly. Each parameter's
values are checked when the study is validated (every level of a categorical parameter, the extremes of a
continuous one, applied to the scene and validated by pydantic); what only a combination of values can
break (a mount that would carry no load) is caught when the batch is built.
"""

from __future__ import annotations

import functools
import itertools
import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeGuard, cast

import numpy as np
import yaml
from pydantic import Field, PrivateAttr, ValidationError, model_validator

from isolab.engine import modal, model
from isolab.engine.results import DOF_NAMES
from isolab.engine.scene import SceneBatch, concat
from isolab.studies.inputs.catalogues import inline_catalogue_file
from isolab.studies.inputs.isolators import mount_labels
from isolab.studies.inputs.parameters import Target, apply, drawn_design, resolve, robust_spreads, scene_dict
from isolab.studies.inputs.scenes import build_batch, check_scene
from isolab.studies.inputs.schema import (
    DesignSpec,
    Floor,
    InputModel,
    ParameterSpec,
    Scene,
    Simulation,
    error_messages,
)
from isolab.studies.questions import designs
from isolab.studies.questions.criteria import Criteria
from isolab.studies.questions.designs import Design, Factor
from isolab.studies.questions.goals import Goals, plan_goals
from isolab.studies.questions.tolerances import Spread, Tolerances
from isolab.studies.units import to_si, written_unit

SAMPLED_TYPES = ("lhs", "sobol", "random", "saltelli", "monte_carlo")
"""Designs whose cases are drawn: ``design.samples`` sets their count (a saltelli design runs
:func:`~isolab.studies.questions.designs.saltelli_cases` of it)."""
_EXTREME_CHECK_LEVELS = 16
DRY_RUN_LIMIT = 200_000
"""Studies of at most this many cases have every case built when they are validated."""
DRY_RUN_CHUNK = 10_000
"""Cases a bad case is looked for among at once when a study is validated: the error reported is the one
a batch of them gives."""
DRY_RUN_BLOCK = 2_000
"""Cases built at once while a chunk is checked (a batch this size stays in the processor's caches: about
1.2 us a case against 1.9 for a whole chunk)."""
REPRESENTATIVE_CASES = 64
"""Most cases whose modes are computed when a study is checked (:meth:`Study._check_statics`)."""


class Study(InputModel):
    """A design of experiments over a scene.

    ``simulation`` given here overrides the scene's simulation block field by field; after validation it
    holds the block every case is simulated with.
    """

    name: str = Field(min_length=1, max_length=200)
    description: str = ""
    scene: Scene | None = None
    scene_file: str | None = Field(
        None, description="scene file, relative to the study file; read only when loading a study file"
    )
    simulation: Simulation = Field(
        cast(Simulation, None),  # not given: the scene's block, which _plan puts here
        description="overrides the scene's simulation block; after validation, the block every case "
        "runs with",
    )
    criteria: Criteria | None = Field(
        None,
        description="replaces the scene's criteria block; after validation, the block the cases are "
        "judged by",
    )
    tolerances: Tolerances | None = Field(
        None,
        description="replaces the scene's tolerances block: each parameter path's spread about its nominal "
        "value (studies.questions.tolerances), what a monte_carlo design draws from",
    )
    floor: Floor | None = Field(
        None, description="replaces the scene's floor block: the same machine on another site's floor"
    )
    parameters: list[ParameterSpec] = Field(default_factory=list)
    design_spec: DesignSpec = Field(default_factory=DesignSpec, alias="design")

    _targets: list[Target] = PrivateAttr(default_factory=list)
    _design: Design | None = PrivateAttr(default=None)
    _groups: dict[tuple, Scene] = PrivateAttr(default_factory=dict)
    _base: dict[str, Any] = PrivateAttr(default_factory=dict)
    _goals: Goals | None = PrivateAttr(default=None)
    _spreads: list[Spread] = PrivateAttr(default_factory=list)

    @model_validator(mode="after")
    def _plan(self) -> Study:
        if self.scene is None:
            raise ValueError(
                "scene: missing; give the scene inline (scene_file is read only when loading a study file)"
            )
        self.simulation = _merged_simulation(self.scene.simulation, self.simulation)
        # the study's own floor and criteria replace the scene's: ``scene`` is then the scene of the study
        if self.floor is not None:
            self.scene = self.scene.model_copy(update={"floor": self.floor})
            self.floor.check_mounts(self.scene.isolators.count)
        if self.criteria is None:
            self.criteria = self.scene.criteria
        else:
            self.scene = self.scene.model_copy(update={"criteria": self.criteria})
        if self.scene.criteria is not None:
            try:
                self.scene.criteria.check_points(self.scene.points, self.scene.has_floor_spectrum())
            except ValueError as err:
                where = "criteria" if self.criteria is not None else "scene.criteria"
                raise ValueError(str(err).replace("criteria", where, 1)) from None
        self._base = scene_dict(self.scene)  # the scene as every case starts from it
        self._base["simulation"] = self.simulation.model_dump(mode="json")
        targets: list[Target] = []
        factors: list[Factor] = []
        for i, p in enumerate(self.parameters):
            try:
                t = resolve(p.path, self.scene)
            except ValueError as err:
                raise ValueError(f"parameters[{i}].path: {err}") from None
            if t.path.split(".")[0] == "simulation" and t.path not in (
                "simulation.duration",
                "simulation.settle_tolerance",
            ):
                raise ValueError(f"parameters[{i}].path: {p.path!r} is shared by every case and cannot vary")
            for j, other in enumerate(targets):
                if set(t.writes) & set(other.writes):
                    raise ValueError(
                        f"parameters[{i}].path: {p.path!r} sets what parameters[{j}] already varies"
                    )
            targets.append(t)
            factors.append(_factor(i, p, t, self.design_spec.type))
        names = [f.name for f in factors]
        for i, n in enumerate(names):
            if n in names[:i]:
                raise ValueError(
                    f"parameters[{i}].name: {n!r} is already the name of parameters[{names.index(n)}]; "
                    "give each a distinct name"
                )
        self._targets = targets
        self._goals = None
        if self.design_spec.type == "optimize":  # checked against the outputs' names; nothing runs
            self._goals = plan_goals(
                self.design_spec, factors, isolator_names(self.scene), list(self.scene.points), self.criteria
            )
        if self.tolerances is not None:
            self.scene = self.scene.model_copy(update={"tolerances": self.tolerances})
        self._spreads = []
        if self.design_spec.sampling is not None and self.design_spec.type != "monte_carlo":
            raise ValueError(
                f"design.sampling: only a monte_carlo design takes it (type: {self.design_spec.type})"
            )
        where = "tolerances" if self.tolerances is not None else "scene.tolerances"
        if self.design_spec.type == "monte_carlo":
            self._targets, self._design, self._spreads = drawn_design(
                self.scene, self.design_spec, where, targets, factors
            )
        else:
            if self._goals is not None and self._goals.robust is not None:
                self._spreads = robust_spreads(self.scene, where, targets, factors)
            self._design = _make_design(self.design_spec, factors, targets)
        self._groups = {}
        return self

    # -----------------------------------------------------------------------------------------------------

    def design(self) -> Design:
        """The cases: a :class:`~studies.questions.designs.Design` (kind, names, values, levels, paths,
        units).

        The design's definition (the ``design:`` block of the input) is ``design_spec``."""
        return cast(Design, self._design)  # _plan, the validator, sets it

    @property
    def base_scene(self) -> Scene:
        """The scene every case starts from: ``scene`` with the study's floor, criteria and tolerances
        (_plan, the validator, requires it)."""
        return cast(Scene, self.scene)

    @property
    def n_cases(self) -> int:
        return self.design().n_cases

    @property
    def goals(self) -> Goals | None:
        """An optimize design's objectives, constraints and settings (:mod:`studies.questions.goals`); else
        None."""
        return self._goals

    @property
    def spreads(self) -> list[Spread]:
        """A monte_carlo design's tolerances resolved in SI about their nominal values, in the order of its
        drawn parameters (:class:`~studies.questions.tolerances.Spread`), or a robust optimize design's
        (an optimised parameter's about the middle of its range, re-centred on each candidate); else
        empty."""
        return list(self._spreads)

    @property
    def planned_cases(self) -> int:
        """Cases the study will run: its design's, or an optimize design's budget (its :meth:`design` then
        holds only the few cases the study is checked with: every parameter at its low, high and middle;
        a robust one runs each candidate's nominal case and draws)."""
        if self._goals is not None:
            return self._goals.budget * self._goals.cases_per_candidate
        return self.n_cases

    @property
    def targets(self) -> list[Target]:
        """Where each parameter goes in the scene, in parameter order."""
        return list(self._targets)

    def batch(self, indices: np.ndarray | list[int] | slice) -> SceneBatch:
        """The engine batch of the cases at ``indices`` (in that order; a slice of the case range works)."""
        if isinstance(indices, slice):
            indices = np.arange(self.n_cases)[indices]
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        if idx.size == 0:
            raise ValueError("indices: no cases")
        if idx.min() < 0 or idx.max() >= self.n_cases:
            raise ValueError(
                f"indices: case numbers run from 0 to {self.n_cases - 1}, got {idx.min()}..{idx.max()}"
            )
        d = self.design()
        cat = [i for i, t in enumerate(self._targets) if t.categorical]
        cont = [i for i, t in enumerate(self._targets) if not t.categorical]
        groups = {(): np.arange(idx.size)}  # without a categorical parameter, one group of every case
        if cat:
            keys = list(zip(*(d.values[d.names[i]][idx].tolist() for i in cat), strict=True))
            positions: dict[tuple, list[int]] = {}
            for k, key in enumerate(keys):
                positions.setdefault(key, []).append(k)
            groups = {key: np.asarray(p) for key, p in positions.items()}
        parts, order = [], []
        for key, pos in groups.items():
            scene = self._group_scene(key, cat)
            overrides = {}
            for i in cont:
                vals = np.asarray(d.values[d.names[i]][idx[pos]], dtype=np.float64)
                for leaf in self._targets[i].writes:
                    overrides[leaf] = vals
            try:
                parts.append(build_batch([scene], overrides, n_cases=pos.size))
            except ValueError as err:
                raise self._case_error(err, idx[pos]) from None
            order.append(pos)
        if len(parts) == 1:
            return parts[0]
        batch = concat(parts)
        inverse = np.empty(idx.size, dtype=np.int64)
        inverse[np.concatenate(order)] = np.arange(idx.size)
        return batch.take(inverse)

    def case_values(self, index: int) -> dict[str, Any]:
        """Parameter name -> value (SI) of one case."""
        d = self.design()
        return {n: d.values[n][index].item() for n in d.names}

    def case_scene(self, index: int) -> Scene:
        """The full, validated scene of one case, with the study's simulation block (slow path: for
        inspection and checks; ``build_batch([study.case_scene(i)])`` equals ``study.batch([i])``)."""
        d = self.design()
        values = [d.values[n][index] for n in d.names]
        return Scene.model_validate(apply(self._base, self._targets, values))

    # -----------------------------------------------------------------------------------------------------

    def _group_scene(self, key: tuple, cat: list[int]) -> Scene:
        if key not in self._groups:
            data = apply(self._base, [self._targets[i] for i in cat], list(key))
            self._groups[key] = Scene.model_validate(data)
        return self._groups[key]

    def _case_error(self, err: ValueError, cases: np.ndarray) -> ValueError:
        """``err`` of a batch of ``cases`` restated with the study's case number and its values."""
        msg = str(err)
        m = re.search(r" \(case (\d+)\)", msg)
        if m and int(m.group(1)) < cases.size:
            case, msg = int(cases[int(m.group(1))]), msg.replace(m.group(0), "")
        elif cases.size == 1:
            case = int(cases[0])
        else:
            return ValueError(f"{msg} (among study cases {cases[:8].tolist()}...)")
        values = ", ".join(
            _shown(v, t) for v, t in zip(self.case_values(case).values(), self._targets, strict=True)
        )
        return ValueError(f"case {case} ({', '.join(self.design().names)} = {values}): {msg}")

    def _check_cases(self) -> None:
        """Build every case (in chunks) so that a combination of values that is not a physical scene is
        reported when the study is validated, not when it runs."""
        n = self.n_cases
        if n > DRY_RUN_LIMIT:
            return
        for start in range(0, n, DRY_RUN_CHUNK):
            chunk = np.arange(start, min(n, start + DRY_RUN_CHUNK))
            try:
                for first in range(0, chunk.size, DRY_RUN_BLOCK):
                    self.batch(chunk[first : first + DRY_RUN_BLOCK])
            except ValueError:
                self.batch(chunk)  # the chunk's own error: the one a batch of all its cases gives
                raise

    def representative_cases(self) -> np.ndarray:
        """A few cases that span the study (at most :data:`REPRESENTATIVE_CASES`): for a grid, the corners
        of its numeric parameters crossed with every level of its categorical ones; for a sampled or listed
        design, the first case and the cases where each parameter takes its extremes (or each of its
        levels)."""
        d = self.design()
        if not d.names:
            return np.zeros(1, dtype=np.int64)
        if d.kind == "grid":
            shape = d.shape
            choices = []
            for size, target in zip(shape, self._targets, strict=True):
                choices.append(range(size) if target.categorical else sorted({0, size - 1}))
            corners = list(itertools.islice(itertools.product(*choices), REPRESENTATIVE_CASES))
            return np.unique(np.ravel_multi_index(np.array(corners).T, shape)).astype(np.int64)
        picks = {0}
        for name, target in zip(d.names, self._targets, strict=True):
            values = d.values[name]
            if target.categorical:
                picks.update(int(np.flatnonzero(values == level)[0]) for level in np.unique(values))
            else:
                picks.update((int(np.argmin(values)), int(np.argmax(values))))
        return np.array(sorted(picks)[:REPRESENTATIVE_CASES], dtype=np.int64)

    def _check_statics(self) -> None:
        """Refuse a study whose every representative case (:meth:`representative_cases`) is a mechanism
        (a mode without stiffness: zero stiffness on the mounts along some direction, or all mounts on one
        line) or tips over (the weights above the mounts rock it more than the mounts hold it): its every
        case would fail. Modal analysis only, nothing is integrated."""
        cases = self.representative_cases()
        batch = self.batch(cases)
        md = modal.modes(model.mass_matrix(batch), model.stiffness_matrix(batch), model.damping_matrix(batch))
        mechanism = md.mechanism.any(axis=1)
        if not (mechanism | md.tipping).all():
            return
        first = 0
        if md.tipping[first]:
            why = (
                "tips over: the rocking stiffness of the weights above the mounts exceeds the mounts' own "
                "(zero or too little stiffness, mounts too close together, or the c.g. too high)"
            )
        else:
            mode = int(np.flatnonzero(md.mechanism[first])[0])
            dof = DOF_NAMES[int(np.argmax(md.energy[first, mode]))]
            why = (
                f"is a mechanism: it moves freely along {dof} with no stiffness to restore it "
                "(zero stiffness on every mount along some direction, or all mounts on one line)"
            )
        what = "the scene" if cases.size == 1 else f"each of the {cases.size} cases that span the study"
        raise ValueError(
            f"isolators: {what} {why}; every case would fail. Give the mounts stiffness in every direction "
            "(k, f_vertical/f_horizontal or a preset) and place them around the c.g."
        )

    def _check_values(self) -> None:
        """Each parameter's levels (or extremes) applied alone to the scene must give a valid scene."""
        d = self.design()
        base = self._base
        for i, (name, target) in enumerate(zip(d.names, self._targets, strict=True)):
            vals = np.unique(d.values[name])
            if vals.size > _EXTREME_CHECK_LEVELS and not target.categorical:
                vals = np.array([vals.min(), vals.max()])
            for v in vals:
                try:
                    check_scene(Scene.model_validate(apply(base, [target], [v])))
                except ValidationError as err:
                    raise ValueError(
                        f"parameters[{i}] ({name}): the value {_shown(v, target)} makes the scene invalid: "
                        + "; ".join(error_messages(err))
                    ) from None
                except ValueError as err:  # the check step's SceneError
                    raise ValueError(
                        f"parameters[{i}] ({name}): the value {_shown(v, target)} makes the scene invalid: "
                        + str(err)
                    ) from None


def _shown(value: Any, target: Target) -> str:
    if target.categorical:
        return str(value)
    return f"{float(value):.6g} {target.unit}".strip()


def _merged_simulation(base: Simulation, given: Simulation | None) -> Simulation:
    if given is None:
        return base
    data = base.model_dump()
    data.update({k: getattr(given, k) for k in given.model_fields_set})
    try:
        return Simulation.model_validate(data)
    except ValidationError as err:
        raise ValueError("simulation: " + "; ".join(error_messages(err))) from None


def _factor(i: int, p: ParameterSpec, t: Target, design_type: str) -> Factor:
    name = p.name or t.name
    where = f"parameters[{i}]"
    if t.categorical:
        if design_type == "saltelli":
            raise ValueError(
                f"{where}.{'range' if p.range is not None else 'values'}: {name} ({t.path}) is categorical "
                f"({', '.join(t.choices)}); a saltelli design varies ranges only: fix it in the scene, or "
                "use an lhs, sobol or grid design"
            )
        if p.range is not None:
            raise ValueError(
                f"{where}.range: {t.path} is categorical; list its values ({', '.join(t.choices)})"
            )
        if p.values is None:
            if design_type == "list":
                return Factor(name, t.path, t.unit, levels=np.array(t.choices))
            raise ValueError(f"{where}.values: give the values of {t.path} ({', '.join(t.choices)})")
        for k, v in enumerate(p.values):
            if v not in t.choices:
                raise ValueError(f"{where}.values[{k}]: {v!r} is not one of {', '.join(t.choices)}")
        return Factor(name, t.path, t.unit, levels=np.array(p.values))
    if p.values is not None:
        if all(type(v) is float or type(v) is int for v in p.values):  # SI numbers: read as one array
            with np.errstate(all="ignore"):
                try:
                    plain = np.asarray(p.values, dtype=np.float64)
                except OverflowError:
                    plain = None
            if plain is not None and np.isfinite(plain).all():
                return Factor(name, t.path, t.unit, levels=plain)
        levels = [to_si(v, t.dimension, f"{where}.values[{k}]") for k, v in enumerate(p.values)]
        shown = _written_unit(p.values, t.dimension)
        return Factor(name, t.path, t.unit, levels=np.array(levels), display_unit=shown)
    if p.range is not None:
        r = p.range
        low = to_si(r.start, t.dimension, f"{where}.range.start")
        high = to_si(r.stop, t.dimension, f"{where}.range.stop")
        try:
            shown = _written_unit([r.start, r.stop], t.dimension)
            return Factor(
                name, t.path, t.unit, low=low, high=high, scale=r.scale, num=r.num, display_unit=shown
            )
        except ValueError as err:
            raise ValueError(f"{where}.range: {err}") from None
    if design_type == "list":
        return Factor(name, t.path, t.unit, low=0.0, high=0.0)  # values come from design.cases
    raise ValueError(f"{where}: give values or range")


def _written_unit(values: list[Any], dimension: str) -> str:
    """The unit the first value written with one was written in (``["0.5 g", "2 g"]`` -> ``"g"``), or ""
    when every value is a plain number (SI): the unit figures show the parameter in."""
    for v in values:
        unit = written_unit(v, dimension)
        if unit is not None:
            return unit
    return ""


_OPTIMIZE_FIELDS = (
    "objective",
    "constraints",
    "algorithm",
    "budget",
    "population",
    "plateau",
    "stall",
    "robust",
)


def _make_design(spec: DesignSpec, factors: list[Factor], targets: list[Target]) -> Design:
    try:
        if spec.type != "optimize":
            given = [k for k in _OPTIMIZE_FIELDS if getattr(spec, k) is not None]
            if given:
                raise ValueError(f"design.{given[0]}: only an optimize design takes it (type: {spec.type})")
        else:  # the cases the study is checked with: each parameter at its low, high and middle together
            checks = [{f.name: float(f.from_unit(np.float64(u))) for f in factors} for u in (0.0, 1.0, 0.5)]
            return designs.explicit(factors, checks)
        if spec.type == "grid":
            for f in factors:
                if f.levels is None and f.num is None:
                    raise ValueError(f"{f.name}: a grid needs values, or a range with num")
            return designs.grid(factors)
        if spec.type in SAMPLED_TYPES:
            if spec.samples is None:
                raise ValueError(f"design.samples: a {spec.type} design needs the number of samples")
            if spec.type == "saltelli":
                for i, f in enumerate(factors):
                    if f.levels is not None:
                        raise ValueError(
                            f"parameters[{i}].values: {f.name} is "
                            + ("categorical" if f.categorical else "a list of values")
                            + "; a saltelli design varies ranges only: give it a range (start, stop), or "
                            "use an lhs, sobol or grid design"
                        )
                return designs.saltelli(
                    factors, spec.samples, spec.seed, bool(spec.second_order), spec.replicates or 1
                )
            make = {"lhs": designs.latin_hypercube, "sobol": designs.sobol, "random": designs.random}[
                spec.type
            ]
            return make(factors, spec.samples, spec.seed)
        if spec.cases is None:
            raise ValueError("design.cases: a list design needs its cases")
        cases = []
        for i, case in enumerate(spec.cases):
            row = {}
            for k, v in case.items():
                named = next((f for f in factors if f.name == k), None)
                if named is not None and not named.categorical:
                    t = targets[factors.index(named)]
                    v = to_si(v, t.dimension, f"design.cases[{i}].{k}")
                row[k] = v
            cases.append(row)
        listed = designs.explicit(factors, cases)
        for f, t in zip(factors, targets, strict=True):  # a parameter given only in the cases: their unit
            if not f.categorical and not f.display_unit:
                written = [case[f.name] for case in spec.cases if f.name in case]
                listed.display_units[f.name] = _written_unit(written, t.dimension) or f.unit
        return listed
    except ValueError as err:
        msg = str(err)
        raise ValueError(
            msg if msg.startswith("design") or msg.startswith("parameters") else f"design: {msg}"
        ) from None


def _is_text(source: str | Path) -> TypeGuard[str]:
    """A string holding YAML/JSON (several lines, or a JSON object) rather than a file name."""
    return isinstance(source, str) and ("\n" in source or source.lstrip().startswith("{"))


def read_definition(source: str | Path, base_dir: str | Path | None = None) -> tuple[dict[str, Any], Path]:
    """The mapping in a YAML/JSON file or text, and the folder relative paths in it start from."""
    if _is_text(source):
        data, where, here = yaml.safe_load(source), "the study text", Path(base_dir or Path.cwd())
    else:
        path = Path(source)
        text = path.read_text(encoding="utf-8")
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
        where, here = str(path), path.resolve().parent
    if not isinstance(data, Mapping):
        raise ValueError(f"{where}: expected a mapping at the top level, got {type(data).__name__}")
    return dict(data), here


# ------------------------------------------------------------------------------ parse -> check -> build
# Validation is three plain steps. Parse: pydantic reads the definition, checks each field and plans the
# design (cheap; builds nothing). Check: what only built scenes show (the base scene's statics, each
# parameter's levels or extremes applied alone, and, up to DRY_RUN_LIMIT cases, every case built once).
# Build: ``Study.batch`` turns cases into engine batches. Whatever a user submits goes through parse and
# check (``validate_study``, ``load_study``); a stored definition, checked when it was submitted, is
# rebuilt with parse alone (``study_from_json``), so a worker never repeats the dry run.


def _check_failed(err: ValueError, loc: tuple[str | int, ...], data: Any, title: str) -> ValidationError:
    """A check-step failure in pydantic's shape (type ``value_error`` at ``loc``), so every caller handles
    one kind of validation error."""
    return ValidationError.from_exception_data(
        title, [{"type": "value_error", "loc": loc, "input": data, "ctx": {"error": err}}]
    )


def check_study(study: Study, data: Any = None) -> Study:
    """The check step of a parsed study: the base scene's statics, each parameter's values applied alone,
    and the dry run of every case (up to ``DRY_RUN_LIMIT``). Returns ``study``.

    Raises:
        pydantic.ValidationError: at ``scene`` for the base scene, at the top for the parameters and cases,
            with the message naming the field (``parameters[0] (...)``, ``case 3 (...)``).
    """
    if study.scene is not None:
        try:
            check_scene(study.scene)
        except ValueError as err:
            raise _check_failed(err, ("scene",), data, "Study") from None
    try:
        study._check_values()
        study._check_cases()
    except ValidationError:
        raise
    except ValueError as err:
        raise _check_failed(err, (), data, "Study") from None
    if study.scene is not None:
        try:
            study._check_statics()
        except ValueError as err:
            raise _check_failed(err, ("scene", "isolators"), data, "Study") from None
    return study


def parse_study(data: Any) -> Study:
    """The parse step: the study read and planned by pydantic (fields, parameter paths, the design)."""
    return Study.model_validate(data)


def validate_study(data: Any) -> Study:
    """Parse and check a study definition given as data (never reads files): what every submission goes
    through. Raises pydantic.ValidationError naming the field."""
    return check_study(parse_study(data), data)


@functools.lru_cache(maxsize=16)
def study_from_json(definition_json: str) -> Study:
    """The study of a stored JSON definition, parsed only (it was checked when it was submitted), cached per
    process: the chunks of one study on one worker share it. Never reads files."""
    return parse_study(json.loads(definition_json))


def validate_scene(data: Any) -> Scene:
    """Parse and check one scene given as data. Raises pydantic.ValidationError naming the field."""
    scene = Scene.model_validate(data)
    try:
        return check_scene(scene)
    except ValueError as err:
        raise _check_failed(err, (), data, "Scene") from None


def load_scene(source: str | Path | Mapping[str, Any]) -> Scene:
    """A validated :class:`~studies.inputs.schema.Scene` from a YAML/JSON file, YAML/JSON text or a dict."""
    if isinstance(source, Mapping):
        return validate_scene(dict(source))
    data, here = read_definition(source)
    return validate_scene(inline_catalogue_file(data, here))


def load_study(source: str | Path | Mapping[str, Any], base_dir: str | Path | None = None) -> Study:
    """A validated :class:`Study` from a YAML/JSON file, YAML/JSON text (a string of several lines or a
    JSON object) or a dict.

    When the study has no inline ``scene``, its ``scene_file`` is read, relative to the study file (for
    text or a dict: relative to ``base_dir``, default the current directory), and becomes the inline
    scene. An inline scene wins over ``scene_file`` (a stored definition keeps both). Services that take
    studies from the network use :func:`validate_study` instead, which never reads files.
    """
    if isinstance(source, Mapping):
        data, here = dict(source), Path(base_dir) if base_dir is not None else Path.cwd()
    else:
        data, here = read_definition(source, base_dir)
    if data.get("scene_file") is not None and data.get("scene") is None:
        scene_path = here / str(data["scene_file"])
        if not scene_path.is_file():
            raise FileNotFoundError(f"scene_file: no file {scene_path}")
        data["scene"], here = read_definition(scene_path)
    data["scene"] = inline_catalogue_file(data.get("scene"), here)
    return validate_study(data)


def isolator_names(scene: Scene) -> list[str]:
    """Labels of the scene's isolators, in batch order (:func:`studies.inputs.isolators.mount_labels`; a
    layout's
    order is :data:`studies.inputs.schema.LAYOUT_ORDER`)."""
    return mount_labels(scene.isolators.count)


def study_labels(study: Study) -> tuple[list[str], list[str]]:
    """(isolator names, point names) of a study's scene, in batch order: the labels of the ``isolator`` and
    ``point`` dimensions of its results (:func:`isolator_names` and the points' own names)."""
    scene = study.base_scene
    return isolator_names(scene), [str(p) for p in scene.points]


def scene_batch(scene: Scene) -> tuple[SceneBatch, dict[str, list[str]]]:
    """The one-case engine batch of ``scene`` and the labels of its isolators, points and stages
    (``{"isolators": [...], "points": [...], "stages": [...]}``, in batch order)."""
    names = {
        "isolators": isolator_names(scene),
        "points": list(scene.points),
        "stages": [s.name for s in scene.stages],
    }
    return build_batch([scene]), names
