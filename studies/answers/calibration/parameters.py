"""The parameters a calibration fits: study parameter paths with bounds and a start, read with units.

A :class:`FitSpec` is what a request or the command line names (:func:`parse_fit` reads
``PATH=LOWER:UPPER[@START]``); :func:`fit_parameters` resolves each against the scene
(:mod:`isolab.studies.inputs.parameters`: ``isolators.f_vertical``, ``isolators.zeta``, ``stages.y.mass``
...) into a :class:`BoundedParameter` in SI, checking that both bounds leave a valid scene.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import ValidationError

from isolab.studies.inputs.definitions import DefinitionError, Loc, detail, validation_details
from isolab.studies.inputs.parameters import Target, apply, resolve, scene_dict
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import validate_scene
from isolab.studies.units import to_si

MAX_PARAMETERS = 8
"""Most parameters one calibration fits (the time offset not counted)."""


@dataclass(frozen=True)
class FitSpec:
    """A parameter to fit: its study parameter path, bounds and optional start (numbers in SI or text
    with units)."""

    path: str
    lower: Any
    upper: Any
    start: Any = None


_FIT = re.compile(
    r"^\s*(?P<path>[^=]+?)\s*=\s*(?P<lower>[^:@]+?)\s*:\s*(?P<upper>[^:@]+?)\s*(?:@\s*(?P<start>.+?))?\s*$"
)


def parse_fit(text: str) -> FitSpec:
    """``"isolators.f_vertical=1:6"`` (or ``"=1 Hz:6 Hz"``, with a start ``"=1:6@3.5"``) as a FitSpec."""
    m = _FIT.match(text)
    if m is None:
        raise ValueError(
            f"--fit {text!r}: write PATH=LOWER:UPPER (e.g. isolators.f_vertical=1:6 or =1 Hz:6 Hz)"
        )
    return FitSpec(m.group("path"), m.group("lower"), m.group("upper"), m.group("start"))


@dataclass
class BoundedParameter:
    """A parameter as the fit moves it: its target, bounds and start in SI (the target's unit), and the
    bounds' width (``scale``, the unit the optimiser steps in)."""

    target: Target
    lower: float
    upper: float
    start: float
    scale: float


def _plain(value: Any, target: Target, loc: Loc) -> float:
    where = ".".join(str(x) for x in loc if x != "body")
    try:
        return to_si(value, target.dimension, where)
    except ValueError as err:
        raise DefinitionError([detail(loc, str(err))]) from None


def _scene_value(scene: Scene, target: Target) -> float | None:
    """The value ``target`` has in ``scene``: a preset's figure where the scene leaves it to the preset,
    the mounts' stiffness or damping along an axis (their mean where they differ) where the scene sets
    them by frequencies."""
    node: Any = scene_dict(scene)
    parts = target.writes[0].split(".")
    for i, part in enumerate(parts):
        if isinstance(node, list):
            if i and parts[i - 1] == "stages":
                node = next((s for s in node if s.get("name") == part), None)
            else:
                node = node[int(part)] if part.isdigit() and int(part) < len(node) else None
        elif isinstance(node, dict):
            node = node.get(part)
        else:
            node = None
        if node is None:
            break
    if isinstance(node, int | float) and not isinstance(node, bool):
        return float(node)
    iso = scene.isolators
    key = parts[-1]
    if parts[0] == "isolators" and len(parts) == 3 and parts[1] in ("k", "c") and key in "xyz":
        batch = build_batch([scene])  # what the mounts have along that axis (from their frequencies)
        values = (batch.iso_k if parts[1] == "k" else batch.iso_c)[0, :, "xyz".index(key)]
        return float(np.mean(values))
    if parts[0] == "isolators" and key in ("f_vertical", "f_horizontal", "zeta"):
        if parts[1] == "list" and iso.mounts is not None:
            mount = iso.mounts[int(parts[2])]
            if mount.preset is not None:
                return float(getattr(iso.preset_of(mount.preset), key))
            own = getattr(iso, key)
            if own is not None:
                return float(own)
        return float(getattr(iso.preset_of(iso.preset), key))
    return None


def fit_parameters(
    scene: Scene, fit: Sequence[FitSpec | Mapping[str, Any]], prefix: Loc
) -> list[BoundedParameter]:
    """The parameters ``fit`` names, resolved against ``scene``: bounds and start in SI, the start the
    scene's own value (clipped to the bounds) unless given, midway where the scene has none.

    Raises:
        DefinitionError: no, too many, unknown, categorical or overlapping parameters, bounds out of
            order or making the scene invalid, each detail under ``prefix + ["fit", i]``.
    """
    if not fit:
        raise DefinitionError([detail([*prefix, "fit"], "name at least one parameter to fit")])
    if len(fit) > MAX_PARAMETERS:
        raise DefinitionError([detail([*prefix, "fit"], f"at most {MAX_PARAMETERS} parameters")])
    out: list[BoundedParameter] = []
    base = scene_dict(scene)
    for i, spec in enumerate(fit):
        loc = [*prefix, "fit", i]
        try:
            s = spec if isinstance(spec, FitSpec) else FitSpec(**dict(spec))
        except TypeError:
            raise DefinitionError(
                [detail(loc, "a parameter to fit is {path, lower, upper, start?}")]
            ) from None
        try:
            t = resolve(s.path, scene)
        except ValueError as err:
            raise DefinitionError([detail([*loc, "path"], str(err))]) from None
        if t.categorical or t.path.split(".")[0] == "simulation":
            raise DefinitionError(
                [detail([*loc, "path"], f"{s.path!r} cannot be fitted: only continuous scene inputs can")]
            )
        for j, other in enumerate(out):
            if set(t.writes) & set(other.target.writes):
                raise DefinitionError([detail([*loc, "path"], f"{s.path!r} sets what fit[{j}] already fits")])
        lo, hi = _plain(s.lower, t, [*loc, "lower"]), _plain(s.upper, t, [*loc, "upper"])
        if not hi > lo:
            raise DefinitionError([detail([*loc, "upper"], f"must be above lower ({lo:g} {t.unit})".strip())])
        if s.start is not None:
            start = _plain(s.start, t, [*loc, "start"])
            if not lo <= start <= hi:
                raise DefinitionError(
                    [detail([*loc, "start"], f"must lie between the bounds {lo:g} and {hi:g}")]
                )
        else:
            current = _scene_value(scene, t)
            start = (lo + hi) / 2.0 if current is None else min(max(current, lo), hi)
        for bound, name in ((lo, "lower"), (hi, "upper")):
            try:
                build_batch([validate_scene(apply(base, [t], [bound]))])
            except (ValueError, ValidationError) as err:
                msg = (
                    "; ".join(d["msg"] for d in validation_details(err, []))
                    if isinstance(err, ValidationError)
                    else str(err)
                )
                raise DefinitionError(
                    [
                        detail(
                            [*loc, name],
                            f"{t.path} = {bound:g} {t.unit} makes the scene invalid: {msg}".strip(),
                        )
                    ]
                ) from None
        out.append(BoundedParameter(t, lo, hi, start, hi - lo))
    return out


def to_si_loc(value: Any, dimension: str, loc: Loc) -> float:
    """:func:`~isolab.studies.units.to_si` raising DefinitionError at ``loc``."""
    try:
        return to_si(value, dimension, ".".join(str(x) for x in loc if x != "body"))
    except ValueError as err:
        raise DefinitionError([detail(loc, str(err))]) from None
