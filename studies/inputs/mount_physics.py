"""Mounts from their physics: each mount's figures from its presets (natural frequencies, damping ratio,
sky-hook, feedforward: :func:`mount_figures`, :func:`mount_feedforward`), air springs (stiffness from
pressure, area and volume; an orifice's relaxation) and mounts on their own axes, applied to a batch's
stiffness and damping arrays; air mounts' levelling valves, applied to a batch's valve arrays.

A scene that gives no ``air``, no ``orientation`` and no ``levelling`` block keeps its arrays untouched;
one without an orifice of ``model: zener`` and without ``elastomer`` has no mount with internal states
(:func:`mount_states`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from isolab.engine import mount_laws
from isolab.engine.linear_states.levelling import MAX_VALVES
from isolab.engine.scene import SceneBatch, SceneError
from isolab.studies.inputs.catalogues import AXIS_DAMPING
from isolab.studies.inputs.isolators import Feedforward, IsolatorPreset
from isolab.studies.inputs.schema.fields import PresetName
from isolab.studies.inputs.schema.mounts import AirSpring, Elastomer, Isolators, Levelling, Orientation
from isolab.studies.inputs.schema.scene_paths import (
    ISOLATORS,
    LEVELLING,
    MOUNT_FIGURES,
    isolator_group,
    mount,
)

if TYPE_CHECKING:
    from isolab.studies.inputs.precision.base_flexibility import CaseValues


def _own_or_group(
    iso: Isolators, j: int, key: str
) -> tuple[AirSpring | Orientation | Elastomer | Levelling | None, str]:
    """A listed mount's own ``key`` block, else the group's, with the path it was given at."""
    listed = iso.listed
    if listed and getattr(listed[j], key) is not None:
        return getattr(listed[j], key), f"{mount(j)}.{key}"
    return getattr(iso, key), f"{ISOLATORS}.{key}"


def _group_of_case(groups: Sequence[Isolators], c: int) -> Isolators:
    """Case ``c``'s isolators of a batch's ``groups``: one shared by every case, or one per case."""
    return groups[0] if len(groups) == 1 else groups[c]


def any_mount_has(groups: Sequence[Isolators], n: int, key: str) -> bool:
    """Whether a mount ``0 <= j < n`` of any case has a ``key`` block, its own or its group's (what
    :func:`_own_or_group` finds): one look per distinct group (``groups``: the batch's isolators, one
    shared by every case or one per case), not per case and mount."""
    distinct = {id(iso): iso for iso in groups}.values()
    return n > 0 and any(
        getattr(iso, key) is not None or any(getattr(m, key) is not None for m in iso.listed[:n])
        for iso in distinct
    )


def axis_damping_ratios(groups: Sequence[Isolators], zeta: np.ndarray, varied: bool = False) -> np.ndarray:
    """(C, n, 3) damping ratio per mount and own axis, 1: ``zeta`` (C, n) on every axis, but where a
    listed mount, or the group below a listed mount's own ``zeta`` or preset, gives ``zeta_horizontal``
    (x, y) or ``zeta_vertical`` (z), that. ``varied``: a study varies ``isolators.zeta``, which then sets
    every axis of the group. ``groups``: the batch's isolators, one shared by every case or one per
    case."""
    out = np.repeat(zeta[..., None], 3, axis=-1)
    distinct = {id(iso): iso for iso in groups}.values()  # the cases of a batch mostly share one group
    if all(getattr(b, key) is None for iso in distinct for b in (iso, *iso.listed) for key in AXIS_DAMPING):
        return out  # no ratio per direction: zeta on every axis
    for key, axes in (("zeta_horizontal", [0, 1]), ("zeta_vertical", [2])):
        for j in range(zeta.shape[1]):
            ratio = np.full(len(groups), np.nan)  # per group, broadcast over the cases below
            for g, iso in enumerate(groups):
                value = None if varied else getattr(iso, key)
                if iso.listed:
                    mt = iso.listed[j]
                    if getattr(mt, key) is not None:
                        value = getattr(mt, key)
                    elif mt.zeta is not None or mt.preset is not None:
                        value = None
                ratio[g] = np.nan if value is None else float(value)
            for a in axes:
                out[:, j, a] = np.where(np.isnan(ratio), out[:, j, a], ratio)
    return out


def apply_mount_physics(
    groups: Sequence[Isolators],
    load: np.ndarray,
    iso_k: np.ndarray,
    iso_c: np.ndarray,
    k_explicit: np.ndarray,
    c_explicit: np.ndarray,
    g: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The batch's stiffness and damping (C, n, 3) with the air springs' physics, and the mounts' own
    axes (C, n, 3, 3), None when no mount has them.

    An air spring sets its mount's z stiffness (N/m) to ``n p_abs A^2 / V`` with the gauge pressure
    ``p = load / A`` (``load`` (C, n) N the static load); with an orifice, z stiffness and damping are the
    standard linear solid's at the mount's own vertical natural frequency
    (``engine.mount_laws.equivalent_viscous``). Explicit ``k``/``c`` of the z axis (``k_explicit``,
    ``c_explicit``, NaN where not given) still win. ``groups``: the batch's isolators, one shared by every
    case or one per case.

    Raises:
        SceneError: naming the air block when its static load is not positive or needs more than its
            ``max_pressure``.
    """
    C, n = load.shape
    air = any_mount_has(groups, n, "air")
    turned = any_mount_has(groups, n, "orientation")
    if not air and not turned:
        return iso_k, iso_c, None
    iso_k, iso_c = iso_k.copy(), iso_c.copy()
    frame = np.broadcast_to(np.eye(3), (C, n, 3, 3)).copy()
    for c in range(C):
        iso = _group_of_case(groups, c)
        for j in range(n):
            turn, _ = _own_or_group(iso, j, "orientation")
            if isinstance(turn, Orientation):
                frame[c, j] = turn.rotation()
            spring, where = _own_or_group(iso, j, "air")
            if not isinstance(spring, AirSpring):
                continue
            f = float(load[c, j])
            case = f" (case {c})" if C > 1 else ""
            if not f > 0.0:
                raise SceneError(
                    where,
                    f"mount {j} carries a static load of {f:.6g} N: an air spring needs one above 0{case}",
                )
            p = float(mount_laws.air_pressure(f, spring.effective_area))
            if spring.max_pressure is not None and p > spring.max_pressure:
                raise SceneError(
                    where,
                    f"mount {j} needs {p / 1e5:.3g} bar to carry {f:.6g} N on "
                    f"{spring.effective_area:.4g} m^2, "
                    f"above its max_pressure of {spring.max_pressure / 1e5:.3g} bar{case}",
                )
            n_exp = spring.polytropic_exponent
            if spring.orifice is None:
                k = float(
                    mount_laws.air_stiffness(
                        p, spring.effective_area, spring.volume + spring.reservoir_volume, n_exp
                    )
                )
                cz = None
            else:
                o = spring.orifice
                k0, k1, tau = mount_laws.air_zener(
                    p,
                    spring.effective_area,
                    spring.volume,
                    spring.reservoir_volume,
                    mount_laws.orifice_resistance(o.area, o.length, o.viscosity),
                    n_exp,
                )
                ke, ce, _ = mount_laws.equivalent_viscous(k0, np.array([k1]), np.array([tau]), f / g)
                k, cz = float(ke), float(ce)
            if np.isnan(k_explicit[c, j, 2]):
                old_k = iso_k[c, j, 2]
                iso_k[c, j, 2] = k
                if cz is not None:
                    cz_set = cz
                elif old_k > 0:  # the preset's damping ratio on the new stiffness: c scales with sqrt(k)
                    cz_set = iso_c[c, j, 2] * np.sqrt(k / old_k)
                else:
                    cz_set = iso_c[c, j, 2]
                if np.isnan(c_explicit[c, j, 2]):
                    iso_c[c, j, 2] = cz_set
    return iso_k, iso_c, frame if turned else None


class IsolatorGroups(Protocol):
    """How the batch builder reads the isolator block of every case."""

    def per_scene(self, read: Callable[[Any], object]) -> list: ...


class MountCases(IsolatorGroups, Protocol):
    """How the batch builder reads the mounts' inputs of ``c`` cases: a leaf (its overrides first), an
    input of each scene, a preset's figures."""

    scenes: Any
    c: int

    def get(self, path: str, read: Any) -> np.ndarray: ...

    def preset(self, iso: Isolators, name: PresetName) -> IsolatorPreset: ...


def first_set(*arrays: np.ndarray) -> np.ndarray:
    """Element-wise the first non-NaN of ``arrays`` (NaN where all are NaN)."""
    out = np.array(arrays[-1], dtype=np.float64, copy=True)
    for a in reversed(arrays[:-1]):
        out = np.where(np.isnan(a), out, a)
    return out


def mount_figures(cases: MountCases, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per case and mount: f_vertical, f_horizontal (Hz), zeta and sky-hook flag, from overrides, the
    mount's own preset, the group's overrides and the group's preset, in that order (a layout's mounts
    share the group's: worked out once)."""
    c = cases.c
    group_preset = cases.per_scene(lambda s: cases.preset(s.isolators, s.isolators.preset))
    listed = cases.scenes[0].isolators.mounts is not None
    out = {}
    for key in MOUNT_FIGURES:

        def group_figure(s: Any, key: str = key) -> float | None:
            return getattr(s.isolators, key)

        group = cases.get(isolator_group(key), group_figure)
        base = np.array([getattr(p, key) for p in group_preset])
        if not listed:
            out[key] = np.stack([first_set(group, base)] * n, axis=-1).reshape(c, n)
            continue
        cols = []
        for j in range(n):

            def own_figure(s: Any, j: int = j, key: str = key) -> float | None:
                return getattr(s.isolators.listed[j], key)

            def own_preset_figure(s: Any, j: int = j, key: str = key) -> float:
                preset = s.isolators.listed[j].preset
                return np.nan if preset is None else getattr(cases.preset(s.isolators, preset), key)

            own = cases.get(f"{mount(j)}.{key}", own_figure)
            own_preset = np.array(cases.per_scene(own_preset_figure), dtype=np.float64)
            cols.append(first_set(own, own_preset, group, base))
        out[key] = np.stack(cols, axis=-1).reshape(c, n)
    sky = np.zeros((c, n), dtype=bool)
    for j in range(n if listed else 1):

        def flag(s: Any, j: int = j) -> bool:
            iso = s.isolators
            if listed:
                mt = iso.listed[j]
                if mt.skyhook is not None:
                    return mt.skyhook
                if mt.preset is not None:
                    return cases.preset(iso, mt.preset).skyhook
            return iso.skyhook if iso.skyhook is not None else cases.preset(iso, iso.preset).skyhook

        mounts = j if listed else slice(None)  # a layout's: every mount
        sky[:, mounts] = np.reshape(cases.per_scene(flag), (-1,) if listed else (-1, 1))
    return out["f_vertical"], out["f_horizontal"], out["zeta"], sky


def mount_feedforward(cases: MountCases, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per case and mount: feedforward gain (1), bandwidth (Hz), actuator force limit (N, inf: none) and
    whether the weight shift is fed forward too (bool).

    The feedforward comes as a whole from the mount's own, its own preset's, the group's or the group
    preset's, in that order; none gives gain 0 (a layout's mounts share the group's: worked out once).
    (Not a design parameter: a study varies it through ``isolators.preset``.)
    """
    listed = cases.scenes[0].isolators.mounts is not None

    def resolved(s: Any, j: int) -> Feedforward | None:
        iso = s.isolators
        if listed:
            mt = iso.listed[j]
            if mt.feedforward is not None:
                return mt.feedforward.figures()
            if mt.preset is not None:
                return cases.preset(iso, mt.preset).feedforward
        if iso.feedforward is not None:
            return iso.feedforward.figures()
        return cases.preset(iso, iso.preset).feedforward

    keys = ("gain", "bandwidth", "force_limit")
    off = {"gain": 0.0, "bandwidth": 0.0, "force_limit": np.inf}
    out = {k: np.zeros((cases.c, n)) for k in keys}
    weight = np.zeros((cases.c, n), dtype=bool)
    for j in range(n if listed else 1):

        def of_mount(s: Any, j: int = j) -> Feedforward | None:
            return resolved(s, j)

        ff = cases.per_scene(of_mount)
        mounts = j if listed else slice(None)  # a layout's: every mount
        column = (-1,) if listed else (-1, 1)
        for key in keys:
            out[key][:, mounts] = np.reshape([off[key] if f is None else getattr(f, key) for f in ff], column)
        weight[:, mounts] = np.reshape([f is not None and f.weight for f in ff], column)
    return out["gain"], out["bandwidth"], out["force_limit"], weight


def elastomer_ladder(spec: Elastomer) -> tuple[np.ndarray, np.ndarray]:
    """An elastomer's branches: stiffness over the static stiffness (B,) and relaxation times (B,) s, from
    its ``ladder`` or fitted (``engine.mount_laws.fit_ladder``; branches of zero stiffness left out)."""
    if spec.ladder is not None:
        return (
            np.array([b.stiffness_ratio for b in spec.ladder], dtype=float),
            np.array([b.relaxation_time for b in spec.ladder], dtype=float),
        )
    _, kb, tau = mount_laws.fit_ladder(
        float(spec.loss_factor or 0.0), float(spec.stiffening or 1.0), spec.f_low, spec.f_high, spec.branches
    )
    return kb[kb > 0], tau[kb > 0]


def mount_states(
    batch: SceneBatch,
    cases: IsolatorGroups,
    load: np.ndarray,
    k_explicit: np.ndarray,
    c_explicit: np.ndarray,
) -> SceneBatch:
    """``batch`` with the mounts' relaxation branches (``iso_branch_k``, ``iso_branch_tau``) where the scene
    asks for them; else ``batch`` itself.

    An air spring whose orifice has ``model: zener`` (and no explicit z stiffness) becomes the standard
    linear solid: its z stiffness the slow one ``n p A^2 / (V + V_r)``, one branch ``n p A^2 / V - k`` with
    the orifice's relaxation time (``engine.mount_laws.air_zener``), no viscous damping (explicit ``c``
    stays). An ``elastomer`` block puts its ladder on each of the mount's own axes, each branch's stiffness
    its ratio times that axis's static stiffness, in place of its viscous damping (explicit ``c`` stays).
    ``load`` (C, n) N is each mount's static load; ``k_explicit``, ``c_explicit`` (C, n, 3) NaN where not
    given.

    Raises:
        SceneError: naming the mount's block when it is both an air spring with states and an elastomer.
    """
    groups = cases.per_scene(lambda s: s.isolators)
    C, n = load.shape
    if not (any_mount_has(groups, n, "air") or any_mount_has(groups, n, "elastomer")):
        return batch  # no mount with internal states
    rows: list[tuple[int, int, int, np.ndarray, np.ndarray]] = []  # (case, mount, axis, k_b, tau_b)
    iso_k = np.array(batch.iso_k, dtype=float)
    iso_c = np.array(batch.iso_c, dtype=float)
    for c in range(C):
        iso = _group_of_case(groups, c)
        for j in range(n):
            spring, _ = _own_or_group(iso, j, "air")
            rubber, where = _own_or_group(iso, j, "elastomer")
            zener = (
                isinstance(spring, AirSpring)
                and spring.orifice is not None
                and spring.orifice.model == "zener"
                and np.isnan(k_explicit[c, j, 2])
            )
            if zener and isinstance(rubber, Elastomer):
                raise SceneError(where, f"mount {j} is an air spring with an orifice state, not an elastomer")
            if zener:
                assert isinstance(spring, AirSpring) and spring.orifice is not None
                o = spring.orifice
                k0, k1, tau = mount_laws.air_zener(
                    mount_laws.air_pressure(float(load[c, j]), spring.effective_area),
                    spring.effective_area,
                    spring.volume,
                    spring.reservoir_volume,
                    mount_laws.orifice_resistance(o.area, o.length, o.viscosity),
                    spring.polytropic_exponent,
                )
                iso_k[c, j, 2] = float(k0)
                if np.isnan(c_explicit[c, j, 2]):
                    iso_c[c, j, 2] = 0.0
                rows.append((c, j, 2, np.array([float(k1)]), np.array([float(tau)])))
            elif isinstance(rubber, Elastomer):
                ratio, tau = elastomer_ladder(rubber)
                for a in range(3):
                    rows.append((c, j, a, ratio * iso_k[c, j, a], tau))
                    if np.isnan(c_explicit[c, j, a]):
                        iso_c[c, j, a] = 0.0
    if not rows:
        return batch
    B = max(r[3].size for r in rows)
    kb = np.zeros((C, n, 3, B))
    tb = np.zeros((C, n, 3, B))
    for c, j, a, k, t in rows:
        kb[c, j, a, : k.size] = k
        tb[c, j, a, : t.size] = t
    return replace(batch, iso_k=iso_k, iso_c=iso_c, iso_branch_k=kb, iso_branch_tau=tb)


def valve_names(iso: Isolators) -> list[str | None]:
    """The name of the levelling valve each mount of ``iso`` is plumbed to (None: no valve). A mount
    whose block names no valve has one of its own (``mount <j>``)."""
    names: list[str | None] = []
    for j in range(iso.count):
        spec, _ = _own_or_group(iso, j, LEVELLING)
        if not isinstance(spec, Levelling):
            names.append(None)
        else:
            names.append(spec.valve if spec.valve is not None else f"mount {j}")
    return names


def valve_signature(iso: Isolators) -> tuple:
    """What scenes of one batch must share of their levelling valves (``()`` without any: the same
    signature as before valves existed)."""
    names = valve_names(iso)
    return () if all(v is None for v in names) else (("valves", tuple(names)),)


def _is_air(iso: Isolators, j: int) -> bool:
    """Whether mount ``j`` is an air mount: its type (own preset, else the group's) is ``air``, or it has an
    ``air`` block."""
    own = iso.listed[j].preset if iso.listed else None
    return (own or iso.preset) == "air" or _own_or_group(iso, j, "air")[0] is not None


def levelling_valves(batch: SceneBatch, cases: CaseValues) -> SceneBatch:
    """``batch`` with its air mounts' levelling valves (``SceneBatch.iso_valve``, ``iso_level_time``,
    ``iso_level_band``), or ``batch`` itself when no mount has one. A study may vary a valve's
    ``time_constant`` and ``dead_band`` (``isolators.levelling.time_constant`` or
    ``isolators.list.<j>.levelling.time_constant``).

    Raises:
        SceneError: naming the ``levelling`` block of a mount that is not an air mount, of a valve whose
            mounts give it different figures, or of the fourth valve.
    """
    iso = cases.scenes[0].isolators
    names = valve_names(iso)
    if all(v is None for v in names):
        return batch
    C, n = batch.n_cases, batch.n_isolators
    order: list[str] = []
    valve = np.full((C, n), -1, dtype=np.int64)
    tau = np.zeros((C, n))
    band = np.zeros((C, n))
    first: dict[str, str] = {}
    for j, name in enumerate(names):
        if name is None:
            continue
        spec, where = _own_or_group(iso, j, LEVELLING)
        if not all(_is_air(s.isolators, j) for s in cases.scenes):
            raise SceneError(
                where, f"mount {j} is not an air mount: a levelling valve belongs to an air mount"
            )
        if name not in order:
            order.append(name)
            if len(order) > MAX_VALVES:
                raise SceneError(
                    where,
                    f"valve {name!r} is the {len(order)}th levelling valve: more than {MAX_VALVES} "
                    "over-determine the base's heave, roll and pitch (the valves would fight and the load "
                    f"split is indeterminate); plumb two mounts to one valve (valve: <name>), three-point "
                    "levelling",
                )
        valve[:, j] = order.index(name)

        def figure(s: object, key: str, j: int = j) -> float:
            block, _ = _own_or_group(s.isolators, j, LEVELLING)  # type: ignore[attr-defined]
            return float(getattr(block, key))

        tau[:, j] = cases.get(f"{where}.time_constant", lambda s: figure(s, "time_constant"))
        band[:, j] = cases.get(f"{where}.dead_band", lambda s: figure(s, "dead_band"))
        if name in first:
            k = names.index(name)
            for key, a in (("time_constant", tau), ("dead_band", band)):
                if (a[:, j] != a[:, k]).any():
                    raise SceneError(
                        f"{where}.{key}",
                        f"mount {j} and mount {k} share valve {name!r} but give it different {key}s; give "
                        "them the same",
                    )
        first.setdefault(name, where)
    return replace(batch, iso_valve=valve, iso_level_time=tau, iso_level_band=band)


def valve_time(batch: SceneBatch) -> np.ndarray:
    """(C,) the longest levelling time constant of a batch's valves, s (0 without any): the slowest decay
    the valves add (the valve's pole sits near ``-1 / time_constant`` on a stiff mount)."""
    t = np.where(np.asarray(batch.iso_valve) >= 0, np.asarray(batch.iso_level_time, dtype=float), 0.0)
    return t.max(axis=1) if t.shape[1] else np.zeros(batch.n_cases)
