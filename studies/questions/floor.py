"""Floor vibration as a spectrum: the generic vibration criteria (VC curves), the user's floor spectrum in
one-third-octave bands, and the velocity spectra it gives at a point of interest.

**Bands.** One-third-octave bands of base 10 (IEC 61260-1): band ``n`` has the exact centre ``10^(n/10)``
Hz and edges a twentieth of a decade either side. isolab uses the twenty bands of nominal centres 1, 1.25,
1.6, ... 63, 80 Hz (``n = 0 .. 19``; :data:`isolab.engine.frequency.BAND_CENTRES`).

**VC curves.** The generic vibration criteria VC-A .. VC-G (:data:`VC_LEVELS`) are RMS velocities in
one-third-octave bands, the same in every band from 1 to 80 Hz: each level halves the one before, from
50 um/s (VC-A). VC-A .. VC-E come from Gordon, "Generic criteria for vibration-sensitive equipment",
Proc. SPIE 1619 (1991); Amick, Gendreau, Busch and Gordon, "Evolving criteria for research facilities:
vibration", Proc. SPIE 5933 (2005) added VC-F and VC-G and made every curve flat down to 1 Hz (the 1991
VC-A and VC-B rose below 8 Hz). :data:`ISO_LEVELS` adds the workshop and office lines of ISO 2631-2 as
drawn on the same charts, only where they are flat (8 to 80 Hz).

**Floor spectrum** (``floor: {spectrum: {x: ..., y: ..., z: ...}}`` of a scene, :class:`isolab.studies.
schema.FloorSpectrum`), per floor axis, an axis left out not moving (axes uncorrelated):

- a VC level (``z: VC-D``): the floor moves at exactly that level in every band from 1 to 80 Hz;
- one-third-octave RMS velocities (``z: {bands: {4 Hz: 20 um/s, 8 Hz: 10 um/s}}``), keyed by the bands'
  nominal (or exact) centres; bands between two given ones are interpolated on log-log axes (a straight
  line on the usual chart), bands below the lowest or above the highest given one are zero. Given bands
  outside 1 to 80 Hz are used for the interpolation only;
- a power spectral density (``z: {psd: {frequency: [...], displacement: [...]}}`` in m^2/Hz, or
  ``velocity: [...]`` in (m/s)^2/Hz, one-sided): interpolated on log-log axes between its points (linearly
  next to a zero), zero outside its frequency range, and integrated over each band to the band's RMS
  velocity ``sqrt(int S_v df)`` (a displacement PSD becomes a velocity PSD by ``(2 pi f)^2``).

The engine takes the result as ``SceneBatch.floor_band_velocity`` (C, 3, 20) m/s: a velocity PSD flat
within each band (:mod:`isolab.engine.frequency`). The spectra it gives at a point, per isolator type, are
:func:`isolab.studies.answers.floor_response.velocity_spectra`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from isolab.engine.frequency import BAND_LOWER, BAND_UPPER, N_BANDS, NOMINAL_CENTRES
from isolab.engine.results import AXES

VC_LEVELS: dict[str, float] = {
    "VC-A": 50e-6,
    "VC-B": 25e-6,
    "VC-C": 12.5e-6,
    "VC-D": 6.25e-6,
    "VC-E": 3.12e-6,
    "VC-F": 1.56e-6,
    "VC-G": 0.78e-6,
}
"""Generic vibration criteria: one-third-octave RMS velocity, m/s, flat from 1 to 80 Hz (Gordon 1991;
Amick, Gendreau, Busch and Gordon 2005)."""
VC_RANGE = (1.0, 80.0)
"""Nominal centres of the first and last band a VC curve covers, Hz."""
ISO_LEVELS: dict[str, float] = {"workshop (ISO)": 800e-6, "office (ISO)": 400e-6}
"""ISO 2631-2 lines of the same charts, one-third-octave RMS velocity, m/s, drawn where flat (8 to 80 Hz)."""
ISO_RANGE = (8.0, 80.0)
"""Nominal centres of the bands the ISO lines are flat over, Hz."""
MAX_BAND_VELOCITY = 0.1
"""Largest floor velocity accepted in one band, m/s (100 mm/s: a floor vibration, not an earthquake)."""
BAND_TOLERANCE = 0.1
"""A band key may lie this far from a band's exact centre, in band numbers ``10 log10(f)`` (2.3 %): the
nominal centres lie within 0.05 of theirs."""
_PSD_POINTS_PER_BAND = 256


def vc_level(name: str) -> float:
    """The RMS band velocity of the VC curve ``name`` (``"VC-D"``, case and spaces ignored), m/s.

    Raises:
        ValueError: ``unknown VC level 'VC-H' (known: VC-A .. VC-G)``.
    """
    key = canonical_vc(name)
    return VC_LEVELS[key]


def canonical_vc(name: str) -> str:
    """``name`` as written in :data:`VC_LEVELS` (``"vc-d"`` -> ``"VC-D"``); ValueError when unknown."""
    key = str(name).strip().upper().replace(" ", "")
    if key not in VC_LEVELS:
        raise ValueError(f"unknown VC level {name!r} (known: {', '.join(VC_LEVELS)})")
    return key


def vc_class(velocity: float) -> str | None:
    """The strictest VC criterion a one-third-octave RMS velocity (m/s) meets (``velocity <= level``);
    None above VC-A or for NaN."""
    met = [name for name, level in VC_LEVELS.items() if velocity <= level]
    return met[-1] if met else None


def band_number(frequency: float) -> int:
    """The number ``n`` of the one-third-octave band whose centre is ``frequency`` (Hz): exact
    ``10^(n/10)`` or nominal (``31.5``); ValueError for a frequency that is no band's centre."""
    f = float(frequency)
    if not (np.isfinite(f) and f > 0.0):
        raise ValueError(f"band {f:g} Hz: a band centre must be a positive frequency")
    x = 10.0 * np.log10(f)
    n = int(np.rint(x))
    if abs(x - n) > BAND_TOLERANCE:
        below, above = 10.0 ** (np.floor(x) / 10.0), 10.0 ** (np.ceil(x) / 10.0)
        raise ValueError(
            f"band {f:g} Hz: not the centre of a one-third-octave band (the nearest are "
            f"{_nominal(below)} Hz and {_nominal(above)} Hz)"
        )
    return n


def _nominal(f: float) -> str:
    n = int(np.rint(10.0 * np.log10(f)))
    if 0 <= n < N_BANDS:
        return f"{NOMINAL_CENTRES[n]:g}"
    return f"{f:.3g}"


def bands_to_levels(bands: Mapping[float, float]) -> np.ndarray:
    """(20,) RMS velocity per band (m/s) from given band levels ``{centre Hz: RMS velocity m/s}``.

    Bands between two given ones: log-log interpolation (linear where one end is zero); outside the given
    ones: zero.
    """
    pts = sorted((band_number(f), float(v)) for f, v in bands.items())
    n = np.array([p[0] for p in pts], dtype=float)
    v = np.array([p[1] for p in pts], dtype=float)
    out = np.zeros(N_BANDS)
    for b in range(N_BANDS):
        if b < n[0] or b > n[-1]:
            continue
        i = int(np.searchsorted(n, b, side="right")) - 1
        if n[i] == b:
            out[b] = v[i]
            continue
        t = (b - n[i]) / (n[i + 1] - n[i])
        lo, hi = v[i], v[i + 1]
        out[b] = lo * (hi / lo) ** t if lo > 0 and hi > 0 else lo + (hi - lo) * t
    return out


def _interp_psd(f: np.ndarray, fp: np.ndarray, sp: np.ndarray) -> np.ndarray:
    """The PSD ``sp`` at ``fp`` read at ``f``: log-log between points (linear next to a zero); zero
    outside ``fp``."""
    i = np.clip(np.searchsorted(fp, f, side="right") - 1, 0, len(fp) - 2)
    f0, f1, s0, s1 = fp[i], fp[i + 1], sp[i], sp[i + 1]
    positive = (s0 > 0) & (s1 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_log = np.log(f / f0) / np.log(f1 / f0)
        loglog = s0 * np.exp(t_log * np.log(np.where(positive, s1 / np.where(s0 > 0, s0, 1.0), 1.0)))
    lin = s0 + (s1 - s0) * (f - f0) / (f1 - f0)
    out = np.where(positive, loglog, lin)
    return np.where((f >= fp[0]) & (f <= fp[-1]), out, 0.0)


def psd_to_levels(frequency: Sequence[float], psd: Sequence[float], kind: str) -> np.ndarray:
    """(20,) RMS velocity per band (m/s) of a one-sided PSD: ``kind`` ``"displacement"`` (m^2/Hz) or
    ``"velocity"`` ((m/s)^2/Hz) at ``frequency`` (Hz, increasing)."""
    fp = np.asarray(frequency, dtype=float)
    sp = np.asarray(psd, dtype=float)
    out = np.zeros(N_BANDS)
    for b in range(N_BANDS):
        lo, hi = max(BAND_LOWER[b], fp[0]), min(BAND_UPPER[b], fp[-1])
        if not hi > lo:
            continue
        f = np.geomspace(lo, hi, _PSD_POINTS_PER_BAND)
        s = _interp_psd(f, fp, sp)
        if kind == "displacement":
            s = s * (2.0 * np.pi * f) ** 2
        out[b] = np.sqrt(max(float(np.trapezoid(s, f)), 0.0))
    return out


def axis_levels(spec: Any) -> np.ndarray:
    """(20,) band RMS velocity (m/s) of one axis of a :class:`~isolab.studies.inputs.schema.FloorSpectrum`
    (a VC name, a bands block or a psd block; None: zero)."""
    if spec is None:
        return np.zeros(N_BANDS)
    if isinstance(spec, str):
        lo, hi = (int(np.rint(10 * np.log10(f))) for f in VC_RANGE)
        out = np.zeros(N_BANDS)
        out[lo : hi + 1] = vc_level(spec)
        return out
    if hasattr(spec, "bands"):
        return bands_to_levels(spec.bands)
    psd = spec.psd
    kind = "displacement" if psd.displacement is not None else "velocity"
    return psd_to_levels(psd.frequency, getattr(psd, kind), kind)


def spectrum_levels(spectrum: Any) -> np.ndarray:
    """(3, 20) band RMS velocity per floor axis (m/s) of a scene's ``floor.spectrum`` (None: zeros)."""
    if spectrum is None:
        return np.zeros((3, N_BANDS))
    return np.stack([axis_levels(getattr(spectrum, a)) for a in AXES])


def scene_band_velocity(scene: Any) -> np.ndarray:
    """(3, 20) band RMS velocity per floor axis (m/s) of a scene's floor spectrum (zeros without one); with
    a spectrum per mount, their root mean square over the mounts."""
    floor = getattr(scene, "floor", None)
    per_mount = None if floor is None else getattr(floor, "per_mount", None)
    if per_mount is not None:
        return np.sqrt(np.mean([spectrum_levels(s) ** 2 for s in per_mount], axis=0))
    return spectrum_levels(None if floor is None else getattr(floor, "spectrum", None))


def scene_mount_band_velocity(scene: Any, n_mounts: int) -> np.ndarray:
    """(n, 3, 20) band RMS velocity per mount and floor axis (m/s): a scene's ``floor.per_mount`` spectra,
    or its one spectrum under every mount."""
    floor = getattr(scene, "floor", None)
    per_mount = None if floor is None else getattr(floor, "per_mount", None)
    if per_mount is not None:
        return np.stack([spectrum_levels(s) for s in per_mount])
    return np.repeat(scene_band_velocity(scene)[None], n_mounts, axis=0)


class SceneValues(Protocol):
    """How the batch builder reads an input of each case's scene (``studies.inputs.scenes``): the scenes
    are one shared by every case, or one per case."""

    def per_scene(self, read: Callable[[Any], object]) -> list:
        """``read`` of each scene."""
        ...

    def array(self, read: Callable[[Any], object]) -> np.ndarray:
        """(C, ...) a fresh float array of ``read`` of each case's scene, read once per scene."""
        ...


def spectrum_fields(cases: SceneValues, iso_pos: np.ndarray, cg: np.ndarray) -> dict:
    """The floor-spectrum fields of an ``engine.scene.SceneBatch`` (``floor_band_velocity`` and, where a
    scene asks for them, ``floor_mount_band_velocity``, ``floor_delay`` and ``floor_coherence``).

    ``cases`` reads the batch's scenes (:class:`SceneValues`); ``iso_pos`` (C, n, 3) and ``cg`` (C, 3), m.
    A travelling wave delays the floor under mount ``j`` by
    ``(r_j - c.g.) . e / speed`` (s).
    """
    c, n = iso_pos.shape[:2]

    def per_case(read: Callable[[Any], object], *shape: int) -> np.ndarray:
        """(C, *shape) a fresh array of ``read`` of each case's scene, read once per scene."""
        return cases.array(read).reshape(c, *shape)

    out: dict[str, Any] = {"floor_band_velocity": per_case(scene_band_velocity, 3, -1)}
    floors = cases.per_scene(lambda s: getattr(s, "floor", None))
    if all(f is None for f in floors):
        return out
    coherence = {getattr(f, "coherence", "correlated") if f is not None else "correlated" for f in floors}
    if len(coherence) > 1:
        raise ValueError(
            f"floor.coherence: the scenes of one batch share one coherence, got {sorted(coherence)}"
        )
    if any(getattr(f, "per_mount", None) is not None for f in floors):
        out["floor_mount_band_velocity"] = per_case(lambda s: scene_mount_band_velocity(s, n), n, 3, N_BANDS)
    if any(getattr(f, "wave", None) is not None for f in floors):
        waves = per_case(
            lambda s: (s.floor.wave.speed, *s.floor.wave.direction) if s.floor.wave else (np.inf, 1.0, 0.0),
            3,
        )
        e = np.concatenate([waves[:, 1:], np.zeros((c, 1))], axis=1)
        out["floor_delay"] = np.einsum("cni,ci->cn", iso_pos - cg[:, None], e) / waves[:, :1]
    out["floor_coherence"] = coherence.pop()
    return out
