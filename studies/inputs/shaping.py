"""Input shaping of the stages' profiles, from a scene's ``profile.shaper`` to the shaped pieces of each case.

A shaper is tuned either to the ``frequency`` and ``damping`` it is given (a study may vary both) or to
one of the scene's own rigid-body modes (``mode``: a number, ascending frequency, or the motion the mode
moves most, :data:`studies.inputs.schema.stages.SHAPER_MODES`), whose frequency and damping ratio are
those of each case: a study that varies the mounts re-tunes the shaper in every case. The modes are those
the engine reports (``natural_frequency``, ``damping_ratio``: undamped frequencies and modal damping with
the stages at home), so a shaper tuned to mode 3 is tuned to ``natural_frequency.3``.

:func:`shaped_profile` shapes one stage's profile (``engine.profiles.shape``); a shaper tuned to a mode
needs the modes of the assembled scene, :func:`scene_modes`, so :func:`studies.inputs.scenes.build_batch`
assembles the batch first and shapes such a profile once the modes are known (:func:`tuned_to_modes`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import numpy as np

from isolab.engine import modal, profiles
from isolab.engine import model as engine_model
from isolab.engine.scene import SceneBatch, SceneError
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.schema.scene_paths import SHAPER_KEYS, profile_shaper
from isolab.studies.inputs.schema.stages import SHAPER_MODES, ShaperSpec

CaseValues = Callable[[str, Callable[[Scene], float | None]], np.ndarray]
"""Reads one numeric input of every case by its path: the study's value where it varies it, else the
scene's (NaN where unset); ``(C,)`` or a scalar broadcast."""
PerScene = Callable[[Callable[[Scene], object]], list]
"""Reads one input of each of the batch's scenes: a list of one, shared by every case, or of ``C``."""


def tuned_to_modes(scene: Scene) -> bool:
    """True when a stage's profile has a shaper tuned to one of the scene's modes."""
    return any(s.profile.shaper is not None and s.profile.shaper.mode is not None for s in scene.stages)


def scene_modes(batch: SceneBatch) -> modal.Modes:
    """The rigid-body modes of each case of ``batch``, with the stages at home: those ``engine.simulate``
    reports."""
    return modal.modes(
        engine_model.mass_matrix(batch),
        engine_model.stiffness_matrix(batch),
        engine_model.damping_matrix(batch),
    )


def mode_index(mode: int | str, modes: modal.Modes) -> np.ndarray:
    """(C,) index (0-based, ascending frequency) of the mode a shaper names: its number, or the mode that
    moves the base most along or about the named motion (``engine.modal.motion_mode``)."""
    if isinstance(mode, int):
        return np.full(modes.frequency.shape[0], mode - 1)
    return modal.motion_mode(modes.energy, SHAPER_MODES[mode])


def _case(bad: np.ndarray) -> str:
    return f" (case {int(np.flatnonzero(bad)[0])})" if bad.size > 1 else ""


def mode_tuning(
    mode: int | str, modes: modal.Modes, cases: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequency (Hz), damping ratio (1) of the mode ``mode`` in the cases ``cases`` (bool (C,)), and
    whether each of them has the mode to tune to (False where the scene tips: it gives no motion).

    Raises:
        SceneError: ``shaper.mode`` of a case whose mode has no frequency (a zero-stiffness mode) or is
            overdamped.
    """
    idx = mode_index(mode, modes)
    rows = np.arange(idx.size)
    f = modes.frequency[rows, idx]
    z = modes.damping_ratio[rows, idx]
    usable = cases & ~modes.tipping
    name = f"mode {mode}" if isinstance(mode, int) else f"the {mode} mode"
    bad = usable & ~(f > 0.0)
    if bad.any():
        raise SceneError(
            "shaper.mode",
            f"{name} has no stiffness (a mechanism): there is no frequency to tune to{_case(bad)}",
        )
    bad = usable & ~(z < 1.0)
    if bad.any():
        c = int(np.flatnonzero(bad)[0])
        raise SceneError(
            "shaper.mode",
            f"{name} is overdamped (damping ratio {z[c]:.3g}): it does not ring, there is nothing to "
            f"shape against{_case(bad)}",
        )
    return f, z, usable


def shaped_profile(
    pc: profiles.Pieces,
    stage: int,
    n_cases: int,
    get: CaseValues,
    per_scene: PerScene,
    modes: modal.Modes | None = None,
) -> profiles.Pieces:
    """Stage ``stage``'s profile ``pc`` through its input shaper, tuned in each of the ``n_cases`` cases.

    ``get`` and ``per_scene`` read the cases' inputs (:data:`CaseValues`, :data:`PerScene`). A shaper tuned to
    a mode takes its frequency and damping ratio from ``modes`` (:func:`scene_modes` of the batch); without
    them such a profile is returned unshaped, to be shaped once they are known. A case that tips keeps
    its profile's motion (an identity shaper: the same pieces as the others).

    Raises:
        SceneError: ``shaper.<field>`` and the reason (see :func:`mode_tuning`,
            ``engine.profiles.shaper_impulses``).
    """
    c = n_cases

    def spec(s: Scene) -> ShaperSpec:  # the batch's scenes share one shape: each of them has the shaper
        return cast(ShaperSpec, s.stages[stage].profile.shaper)

    def on_cases(flags: list[bool]) -> np.ndarray:
        """(C,) bool of flags per scene."""
        return np.broadcast_to(np.array(flags, dtype=bool), (c,))

    kinds = per_scene(lambda s: spec(s).type)
    tuned = per_scene(lambda s: spec(s).mode)
    if modes is None and any(m is not None for m in tuned):
        return pc
    q = profile_shaper(per_scene(lambda s: s.stages[stage].name)[0])

    def figure(key: str) -> np.ndarray:
        return np.broadcast_to(get(f"{q}.{key}", lambda s: getattr(spec(s), key)), (c,))

    f, z = (np.array(figure(key), dtype=np.float64) for key in SHAPER_KEYS)
    z[np.isnan(z)] = 0.0  # an undamped mode unless the damping is given (or the mode's, below)
    identity = np.zeros(c, dtype=bool)
    for mode in {m for m in tuned if m is not None}:
        on = on_cases([m == mode for m in tuned])
        fm, zm, usable = mode_tuning(mode, cast(modal.Modes, modes), on)
        f[usable], z[usable] = fm[usable], zm[usable]
        identity |= on & ~usable
    t = np.zeros((c, profiles.SHAPER_IMPULSES))
    a = np.zeros((c, profiles.SHAPER_IMPULSES))
    a[identity, 0] = 1.0
    for kind in set(kinds):
        on = on_cases([k == kind for k in kinds]) & ~identity
        if on.any():
            t[on], a[on] = profiles.shaper_impulses(kind, f[on], z[on])
    return profiles.shape(profiles.Pieces(*(np.broadcast_to(x, (c, x.shape[1])) for x in pc)), t, a)
