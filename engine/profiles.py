"""Stage motion profiles: trapezoidal, jerk-limited S-curve, sequences of moves and dwells, scans.

A profile is a piecewise polynomial in time stored as ``K`` pieces (see :mod:`engine.scene`). Piece ``k``
starts at time ``t[k]`` (s) with position ``s[k]`` (m), velocity ``v[k]`` (m/s), acceleration ``a[k]``
(m/s^2) and constant jerk ``j[k]`` (m/s^3), and holds until ``t[k + 1]``; the last piece holds forever.
Within piece ``k``, with ``tau = t - t[k]``::

    s = s[k] + v[k] tau + a[k] tau^2 / 2 + j[k] tau^3 / 6
    v = v[k] + a[k] tau + j[k] tau^2 / 2
    a = a[k] + j[k] tau

Start times are non-decreasing. Each profile kind has a fixed number of pieces whatever the values
(phases a case does not need keep zero length), so the cases of a batch share ``K``. The last piece is a
rest piece (``v = a = j = 0``) at the final position.

Every builder is vectorised over cases: scalar or ``(C,)`` inputs broadcast to ``C`` cases and every
output array has shape ``(C, K)``. Position and velocity at the start of a piece are obtained by evaluating
the previous piece at its end, so both are continuous to rounding; the final velocity is exactly zero and
the final position of a move is exactly ``s0 + distance``. Breakpoints are absolute times, so a phase
lasts what its stored start times say only to the float spacing ``ulp(t)`` near them: measured from
the stored times, velocity may jump by up to ``|a| ulp(t)`` and position by ``|v| ulp(t)`` at a
breakpoint (e.g. 2e-13 m/s for 100 m/s^2 at t = 10 s).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from isolab.engine.scene import SceneError

TRAPEZOID_PIECES = 4
"""Pieces of a trapezoidal move: accelerate, cruise, decelerate, rest."""
SCURVE_PIECES = 8
"""Pieces of an S-curve move: seven jerk-limited phases, rest."""


class Pieces(NamedTuple):
    """Piecewise-polynomial motion of ``C`` cases (one stage each, or ``(C, m, K)`` after :func:`stack`).

    Attributes (shape (C, K) or (C, m, K); units):
        t: piece start time, s.
        s: position at the piece start, m.
        v: velocity at the piece start, m/s.
        a: acceleration at the piece start, m/s^2.
        j: constant jerk over the piece, m/s^3.
    """

    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    a: np.ndarray
    j: np.ndarray

    @property
    def n_cases(self) -> int:
        return int(self.t.shape[0])

    @property
    def n_pieces(self) -> int:
        return int(self.t.shape[-1])


# ---------------------------------------------------------------------------------------------------------
# input checks


def _numbers(name: str, value: ArrayLike) -> np.ndarray:
    """``value`` as a float64 array of at most one dimension (the cases)."""
    try:
        x = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(name, f"must be a number or a 1-D array of numbers, got {value!r}") from None
    if x.ndim > 1:
        raise SceneError(name, f"must be a number or a 1-D array over cases, got shape {x.shape}")
    if x.size == 0:
        raise SceneError(name, "must not be empty")
    return x


def _first_bad(x: np.ndarray, bad: np.ndarray) -> str:
    return f"{float(x.reshape(-1)[np.flatnonzero(bad)[0]]):g}"


def _finite(name: str, value: ArrayLike) -> np.ndarray:
    x = _numbers(name, value)
    bad = ~np.isfinite(x)
    if bad.any():
        raise SceneError(name, f"must be finite, got {_first_bad(x, bad)}")
    return x


def _positive(name: str, value: ArrayLike) -> np.ndarray:
    x = _numbers(name, value)
    bad = ~(np.isfinite(x) & (x > 0.0))
    if bad.any():
        raise SceneError(name, f"must be positive and finite, got {_first_bad(x, bad)}")
    return x


def _non_negative(name: str, value: ArrayLike) -> np.ndarray:
    x = _numbers(name, value)
    bad = ~(np.isfinite(x) & (x >= 0.0))
    if bad.any():
        raise SceneError(name, f"must be non-negative and finite, got {_first_bad(x, bad)}")
    return x


def _n_cases(named: Mapping[str, np.ndarray]) -> int:
    """Number of cases the inputs broadcast to; an input of another length than the rest is an error."""
    c = 1
    for x in named.values():
        if x.size != 1:
            c = x.size if c == 1 else c
    for name, x in named.items():
        if x.size not in (1, c):
            raise SceneError(name, f"has {x.size} values but the other inputs have {c} cases")
    return c


def _cases(named: Mapping[str, np.ndarray], c: int | None = None) -> list[np.ndarray]:
    c = _n_cases(named) if c is None else c
    out = []
    for name, x in named.items():
        if x.size not in (1, c):
            raise SceneError(name, f"has {x.size} values but the other inputs have {c} cases")
        out.append(np.broadcast_to(x.reshape(-1), (c,)).astype(np.float64))
    return out


# ---------------------------------------------------------------------------------------------------------
# piece arithmetic


def _advance(
    s: np.ndarray, v: np.ndarray, a: np.ndarray, j: np.ndarray, tau: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration ``tau`` seconds after the start of a piece."""
    s1 = s + v * tau + a * (tau * tau) / 2.0 + j * (tau * tau * tau) / 6.0
    v1 = v + a * tau + j * (tau * tau) / 2.0
    a1 = a + j * tau
    return s1, v1, a1


def _chain(
    start: np.ndarray,
    s0: np.ndarray,
    target: np.ndarray,
    durations: Sequence[np.ndarray],
    accel: Sequence[np.ndarray],
    jerk: Sequence[np.ndarray],
) -> Pieces:
    """Pieces of one move from rest at ``s0``: given phases, then a rest piece exactly at ``target``.

    ``accel[k]`` is the acceleration set at the start of phase ``k`` (so a phase of constant acceleration
    has exactly that value); position and velocity follow from evaluating the previous phase at its end.
    """
    zero = np.zeros_like(start)
    ts, ss, vs, acc, jer = [start], [s0], [zero], [], []
    for dur, a_k, j_k in zip(durations, accel, jerk, strict=True):
        a_k = np.broadcast_to(a_k, start.shape).astype(np.float64)
        j_k = np.broadcast_to(j_k, start.shape).astype(np.float64)
        acc.append(a_k)
        jer.append(j_k)
        s1, v1, _ = _advance(ss[-1], vs[-1], a_k, j_k, dur)
        ts.append(ts[-1] + dur)
        ss.append(s1)
        vs.append(v1)
    # the rest piece: set, not accumulated
    ss[-1] = target.copy()
    vs[-1] = zero
    acc.append(zero)
    jer.append(zero)
    return Pieces(*(np.stack(col, axis=-1) for col in (ts, ss, vs, acc, jer)))


# ---------------------------------------------------------------------------------------------------------
# moves


def _trapezoid(
    d: np.ndarray, v_max: np.ndarray, a_max: np.ndarray, start: np.ndarray, s0: np.ndarray
) -> Pieces:
    sgn = np.sign(d)
    dist = np.abs(d)
    v_peak = np.minimum(v_max, np.sqrt(dist * a_max))
    t_acc = v_peak / a_max
    cruising = v_peak >= v_max  # else triangular: the cruise piece keeps zero length
    t_cruise = np.where(cruising, np.maximum(dist / v_max - t_acc, 0.0), 0.0)
    zero = np.zeros_like(d)
    return _chain(
        start,
        s0,
        s0 + d,
        durations=(t_acc, t_cruise, t_acc),
        accel=(sgn * a_max, zero, -sgn * a_max),
        jerk=(zero, zero, zero),
    )


def _scurve(
    d: np.ndarray, v_max: np.ndarray, a_max: np.ndarray, j_max: np.ndarray, start: np.ndarray, s0: np.ndarray
) -> Pieces:
    sgn = np.sign(d)
    dist = np.abs(d)
    A, J = a_max, j_max
    # distance to reach v_max and come back to rest (accel and decel phases alike)
    reach_at_vmax = v_max * J >= A * A
    t_acc_vmax = np.where(reach_at_vmax, v_max / A + A / J, 2.0 * np.sqrt(v_max / J))
    full = v_max * t_acc_vmax <= dist
    # shorter moves: the reduced peak velocity that makes accel + decel cover the distance exactly
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        reach_short = dist >= 2.0 * A**3 / (J * J)  # a_max still reached
        b = A * A / J  # v^2 + b v - A d = 0, stable root
        v_reach = 2.0 * A * dist / (b + np.sqrt(b * b + 4.0 * A * dist))
        v_no_reach = np.cbrt(dist * dist * J / 4.0)
    v_peak = np.where(full, v_max, np.where(reach_short, v_reach, v_no_reach))
    reach = np.where(full, reach_at_vmax, reach_short)
    a_peak = np.where(reach, A, np.sqrt(v_peak * J))
    t_jerk = a_peak / J
    t_const = np.where(reach, np.maximum(v_peak / A - A / J, 0.0), 0.0)
    t_acc = 2.0 * t_jerk + t_const
    t_cruise = np.where(full, np.maximum(dist / v_max - t_acc, 0.0), 0.0)
    zero = np.zeros_like(d)
    ap, jp = sgn * a_peak, sgn * J
    return _chain(
        start,
        s0,
        s0 + d,
        durations=(t_jerk, t_const, t_jerk, t_cruise, t_jerk, t_const, t_jerk),
        accel=(zero, ap, ap, zero, zero, -ap, -ap),
        jerk=(jp, zero, -jp, zero, -jp, zero, jp),
    )


def trapezoid(
    distance: ArrayLike, v_max: ArrayLike, a_max: ArrayLike, start: ArrayLike = 0.0, s0: ArrayLike = 0.0
) -> Pieces:
    """Trapezoidal move by signed ``distance`` (m) from rest at ``s0`` (m), starting at ``start`` (s).

    Accelerates at ``a_max`` (m/s^2) to ``v_max`` (m/s), cruises, decelerates at ``a_max``: ``K = 4``
    pieces (accelerate, cruise, decelerate, rest). When ``|distance| < v_max^2 / a_max`` the move is
    triangular: peak velocity ``sqrt(|distance| a_max)`` and a zero-length cruise piece. A zero distance
    gives four zero-length pieces at rest at ``s0``.
    """
    named = {
        "distance": _finite("distance", distance),
        "v_max": _positive("v_max", v_max),
        "a_max": _positive("a_max", a_max),
        "start": _finite("start", start),
        "s0": _finite("s0", s0),
    }
    d, v, a, t0, x0 = _cases(named)
    return _trapezoid(d, v, a, t0, x0)


def scurve(
    distance: ArrayLike,
    v_max: ArrayLike,
    a_max: ArrayLike,
    j_max: ArrayLike,
    start: ArrayLike = 0.0,
    s0: ArrayLike = 0.0,
) -> Pieces:
    """Jerk-limited (seven-phase S-curve) move by signed ``distance`` (m) from rest at ``s0`` (m).

    Phases: jerk up at ``j_max`` (m/s^3), constant acceleration ``a_max`` (m/s^2), jerk down, cruise at
    ``v_max`` (m/s), then the mirror image to rest; ``K = 8`` pieces (seven phases, rest), starting at
    ``start`` (s). With all phases present the duration is ``d/v + v/a + a/j``. When ``v_max j_max < a_max^2``
    the acceleration peaks at ``sqrt(v j_max)`` below ``a_max`` (constant-acceleration phases of zero
    length). When the distance is too short to reach ``v_max`` the peak velocity is reduced exactly so that
    acceleration and deceleration cover the distance: ``v^2/a + v a/j = d`` when ``a_max`` is still reached,
    else ``v = (d^2 j / 4)^(1/3)``; the cruise phase then has zero length.
    """
    named = {
        "distance": _finite("distance", distance),
        "v_max": _positive("v_max", v_max),
        "a_max": _positive("a_max", a_max),
        "j_max": _positive("j_max", j_max),
        "start": _finite("start", start),
        "s0": _finite("s0", s0),
    }
    d, v, a, j, t0, x0 = _cases(named)
    return _scurve(d, v, a, j, t0, x0)


# ---------------------------------------------------------------------------------------------------------
# sequences


_MOVE_KEYS = {"move", "v_max", "a_max", "j_max"}


def _check_segment(i: int, seg: object) -> dict[str, np.ndarray]:
    """The checked values of segment ``i``: ``dwell`` (s), or ``move`` (m), ``v_max`` (m/s), ``a_max``
    (m/s^2) and, for an S-curve, ``j_max`` (m/s^3)."""
    where = f"segments[{i}]"
    if not isinstance(seg, Mapping):
        raise SceneError(where, f"must be a mapping with 'move' or 'dwell', got {type(seg).__name__}")
    keys = set(seg)
    if ("move" in keys) == ("dwell" in keys):
        raise SceneError(where, f"must have exactly one of 'move' or 'dwell', got keys {sorted(keys)}")
    if "dwell" in keys:
        if keys != {"dwell"}:
            raise SceneError(where, f"a dwell takes only 'dwell', got extra keys {sorted(keys - {'dwell'})}")
        return {"dwell": _non_negative(f"{where}.dwell", seg["dwell"])}
    unknown = keys - _MOVE_KEYS
    if unknown:
        raise SceneError(where, f"unknown keys {sorted(unknown)} (a move takes {sorted(_MOVE_KEYS)})")
    for key in ("v_max", "a_max"):
        if key not in keys:
            raise SceneError(f"{where}.{key}", "is required for a move")
    out = {
        "move": _finite(f"{where}.move", seg["move"]),
        "v_max": _positive(f"{where}.v_max", seg["v_max"]),
        "a_max": _positive(f"{where}.a_max", seg["a_max"]),
    }
    if seg.get("j_max") is not None:
        out["j_max"] = _positive(f"{where}.j_max", seg["j_max"])
    return out


def sequence(
    segments: Sequence[Mapping[str, ArrayLike]], start: ArrayLike = 0.0, s0: ArrayLike = 0.0
) -> Pieces:
    """Moves and dwells one after the other, from rest at ``s0`` (m) at time ``start`` (s).

    Each segment is ``{"move": distance, "v_max": ..., "a_max": ..., "j_max": ...}`` (m, m/s, m/s^2,
    m/s^3; ``j_max`` optional: with it an S-curve, without it a trapezoid) or ``{"dwell": seconds}``.
    Values may be ``(C,)`` arrays. Each move contributes its pieces but its rest piece (3 for a trapezoid,
    7 for an S-curve), each dwell one rest piece, and one rest piece ends the profile, so ``K`` depends on
    the segment list only. An empty list gives a single rest piece at ``s0``.
    """
    if isinstance(segments, Mapping) or not isinstance(segments, Sequence):
        raise SceneError("segments", f"must be a list of moves and dwells, got {type(segments).__name__}")
    checked = [_check_segment(i, seg) for i, seg in enumerate(segments)]
    named = {"start": _finite("start", start), "s0": _finite("s0", s0)}
    for i, seg in enumerate(checked):
        for key, x in seg.items():
            named[f"segments[{i}].{key}"] = x
    c = _n_cases(named)
    t_now, s_now = _cases({"start": named["start"], "s0": named["s0"]}, c)
    zero = np.zeros(c)
    cols: list[list[np.ndarray]] = [[], [], [], [], []]
    for seg in checked:
        if "dwell" in seg:
            (dwell,) = _cases({"dwell": seg["dwell"]}, c)
            for col, x in zip(cols, (t_now, s_now, zero, zero, zero), strict=True):
                col.append(x[:, None])
            t_now = t_now + dwell
            continue
        d, v, a = _cases({"move": seg["move"], "v_max": seg["v_max"], "a_max": seg["a_max"]}, c)
        if "j_max" not in seg:
            p = _trapezoid(d, v, a, t_now, s_now)
        else:
            (j,) = _cases({"j_max": seg["j_max"]}, c)
            p = _scurve(d, v, a, j, t_now, s_now)
        for col, x in zip(cols, p, strict=True):
            col.append(x[:, :-1])
        t_now, s_now = p.t[:, -1], p.s[:, -1]
    for col, x in zip(cols, (t_now, s_now, zero, zero, zero), strict=True):
        col.append(x[:, None])
    return Pieces(*(np.concatenate(col, axis=-1) for col in cols))


def scan(
    travel: ArrayLike,
    v_max: ArrayLike,
    a_max: ArrayLike,
    j_max: ArrayLike | None = None,
    dwell: ArrayLike = 0.0,
    repeats: int = 1,
    start: ArrayLike = 0.0,
) -> Pieces:
    """Back-and-forth scan from rest at 0: out by ``+travel`` (m), dwell, back by ``-travel``, dwell.

    The cycle is repeated ``repeats`` times (the same integer for all cases). Moves are S-curves when
    ``j_max`` (m/s^3) is given, else trapezoids, limited by ``v_max`` (m/s) and ``a_max`` (m/s^2);
    ``dwell`` in s (may be 0: the dwell pieces keep zero length). The profile ends (see :func:`end_time`)
    after the last dwell, back at exactly 0.
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int | np.integer) or repeats < 1:
        raise SceneError("repeats", f"must be an integer >= 1, got {repeats!r}")
    named = {
        "travel": _finite("travel", travel),
        "v_max": _positive("v_max", v_max),
        "a_max": _positive("a_max", a_max),
        "dwell": _non_negative("dwell", dwell),
        "start": _finite("start", start),
    }
    if j_max is not None:
        named["j_max"] = _positive("j_max", j_max)
    _n_cases(named)  # report a length mismatch under the caller's argument names
    limits = {"v_max": named["v_max"], "a_max": named["a_max"]}
    if j_max is not None:
        limits["j_max"] = named["j_max"]
    out = {"move": named["travel"], **limits}
    back = {"move": -named["travel"], **limits}
    pause = {"dwell": named["dwell"]}
    return sequence([out, pause, back, pause] * int(repeats), start=named["start"], s0=0.0)


# ---------------------------------------------------------------------------------------------------------
# input shaping

SHAPERS = ("zv", "zvd", "ei")
"""Input shapers (docs/physics.md, "Input shaping"): zero vibration, zero vibration and derivative, extra
insensitive (5 % vibration tolerated at the tuned frequency)."""
SHAPER_IMPULSES = 3
"""Impulses of every shaper (a ZV shaper's third has zero amplitude), so that shaped profiles of one
stage share their piece count whatever the shaper."""
EI_TOLERANCE = 0.05
"""The residual vibration an EI shaper tolerates at its tuned frequency, 1."""


def shaper_impulses(kind: str, frequency: ArrayLike, damping: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Impulse times (C, 3), s, and amplitudes (C, 3), 1 (summing to 1), of a shaper tuned to a mode of
    ``frequency`` (Hz) and damping ratio ``damping`` (1, below 1).

    With ``K = exp(-zeta pi / sqrt(1 - zeta^2))`` and the damped half period ``T = 1 / (2 f sqrt(1 -
    zeta^2))``: ZV ``[1, K] / (1 + K)`` at ``[0, T]``; ZVD ``[1, 2K, K^2] / (1 + K)^2`` at ``[0, T, 2T]``; EI
    ``[(1 + V)/4, (1 - V)/2 K, (1 + V)/4 K^2]`` normalised, at ``[0, T, 2T]`` (``V`` :data:`EI_TOLERANCE`;
    the undamped EI shaper, weighted by the damping as ZVD is).
    """
    if kind not in SHAPERS:
        raise SceneError("shaper.type", f"must be one of {', '.join(SHAPERS)}, got {kind!r}")
    named = {"shaper.frequency": _positive("shaper.frequency", frequency)}
    named["shaper.damping"] = _non_negative("shaper.damping", damping)
    f, z = _cases(named)
    if np.any(z >= 1.0):
        raise SceneError("shaper.damping", f"must be below 1 (an underdamped mode), got {z.max():g}")
    root = np.sqrt(1.0 - z * z)
    K = np.exp(-z * np.pi / root)
    half = 1.0 / (2.0 * f * root)
    zero = np.zeros_like(f)
    if kind == "zv":
        t = np.stack([zero, half, half], axis=-1)
        a = np.stack([np.ones_like(K), K, zero], axis=-1)
    else:
        t = np.stack([zero, half, 2.0 * half], axis=-1)
        w = (
            (1.0, 2.0, 1.0)
            if kind == "zvd"
            else ((1 + EI_TOLERANCE) / 4, (1 - EI_TOLERANCE) / 2, (1 + EI_TOLERANCE) / 4)
        )
        a = np.stack([w[0] * np.ones_like(K), w[1] * K, w[2] * K * K], axis=-1)
    return t, a / a.sum(axis=-1, keepdims=True)


def shape(p: Pieces, times: np.ndarray, amplitudes: np.ndarray) -> Pieces:
    """The profile ``p`` (C, K) convolved with the impulses ``amplitudes`` (C, N), 1, at ``times`` (C, N),
    s, from 0: ``s_shaped(t) = sum_i A_i s(t - t_i)``. Its acceleration is the profile's convolved with the
    impulses, it ends where the profile ends (``sum A_i = 1``; the final position is set exactly), and the
    move lasts longer by the last impulse's time. The result has ``K N`` pieces (at every ``t_k + t_i``,
    sorted; coinciding breakpoints keep zero-length pieces), each cubic as the profile's are."""
    tk = np.asarray(p.t, dtype=np.float64)
    C, K = tk.shape
    times = np.broadcast_to(np.asarray(times, dtype=np.float64), (C, np.shape(times)[-1]))
    amps = np.broadcast_to(np.asarray(amplitudes, dtype=np.float64), times.shape)
    N = times.shape[1]
    starts = np.sort((tk[:, :, None] + times[:, None, :]).reshape(C, K * N), axis=1)
    cols = [starts, np.zeros((C, K * N)), np.zeros((C, K * N)), np.zeros((C, K * N)), np.zeros((C, K * N))]
    for i in range(N):
        # the copy's piece at each breakpoint (right limit), compared in shifted times, which are the
        # breakpoints' own sums: a copy's own breakpoints find their piece exactly, whatever the rounding
        shifted = tk + times[:, i : i + 1]
        idx = np.zeros((C, K * N), dtype=np.intp)
        for k in range(1, K):
            idx += shifted[:, k : k + 1] <= starts
        pick = [np.take_along_axis(np.asarray(x, dtype=np.float64), idx, axis=1) for x in p]
        tau = starts - np.take_along_axis(shifted, idx, axis=1)
        s, v, a = _advance(pick[1], pick[2], pick[3], pick[4], tau)
        j = pick[4]
        before = starts < shifted[:, :1]  # at rest before the profile starts
        s = np.where(before, p.s[:, :1], s)
        v, a, j = (np.where(before, 0.0, x) for x in (v, a, j))
        A = amps[:, i : i + 1]
        for col, x in zip(cols[1:], (s, v, a, j), strict=True):
            col += A * x
    cols[1][:, -1] = p.s[:, -1]
    for col in cols[2:]:
        col[:, -1] = 0.0
    return Pieces(*cols)


def shaped_move_time(p: Pieces, shaped: Pieces) -> np.ndarray:
    """What shaping costs in move time (C,), s: the end of the shaped motion minus the profile's."""
    return end_time(shaped) - end_time(p)


# ---------------------------------------------------------------------------------------------------------
# evaluation and batching


def evaluate(p: Pieces, t: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position (m), velocity (m/s) and acceleration (m/s^2) at times ``t`` (s, shape (T,)).

    Works on pieces of shape (C, K) (or (C, m, K)) and returns arrays of shape (C, T) (or (C, m, T)). At a
    breakpoint the piece that starts there is used (right limit). Before the first piece starts the stage
    is at rest at its initial position.
    """
    tt = _numbers("t", t)
    if tt.ndim == 0:
        tt = tt.reshape(1)
    if not np.all(np.isfinite(tt)):
        raise SceneError("t", "must be finite")
    tk = np.asarray(p.t, dtype=np.float64)
    idx = np.zeros(tk.shape[:-1] + tt.shape, dtype=np.intp)
    for k in range(1, tk.shape[-1]):
        idx += tk[..., k : k + 1] <= tt

    def pick(x: np.ndarray) -> np.ndarray:
        return np.take_along_axis(np.asarray(x, dtype=np.float64), idx, axis=-1)

    tau = tt - pick(tk)
    s, v, a = _advance(pick(p.s), pick(p.v), pick(p.a), pick(p.j), tau)
    before = tt < tk[..., :1]
    if before.any():
        s = np.where(before, p.s[..., :1], s)
        v = np.where(before, 0.0, v)
        a = np.where(before, 0.0, a)
    return s, v, a


def end_time(p: Pieces) -> np.ndarray:
    """Time at which the motion ends: start of the final rest piece, s (shape (C,) or (C, m))."""
    return np.asarray(p.t)[..., -1].copy()


def stack(stages: Sequence[Pieces]) -> Pieces:
    """Profiles of ``m`` stages as one ``(C, m, K)`` batch, ``K`` the largest piece count.

    A stage with fewer pieces is padded at the end with zero-length rest pieces at its final time and
    position; a stage given for one case is repeated over the ``C`` cases of the others.
    """
    if len(stages) == 0:
        raise SceneError("stages", "must hold at least one profile")
    for i, p in enumerate(stages):
        if np.ndim(p.t) != 2 or any(np.shape(x) != np.shape(p.t) for x in p):
            raise SceneError(f"stages[{i}]", "must be Pieces with arrays of shape (C, K)")
    sizes = {f"stages[{i}]": np.zeros(p.t.shape[0]) for i, p in enumerate(stages)}
    c = _n_cases(sizes)
    k_max = max(p.t.shape[1] for p in stages)
    cols: list[list[np.ndarray]] = [[], [], [], [], []]
    for p in stages:
        pad = k_max - p.t.shape[1]
        rest = (p.t[:, -1:], p.s[:, -1:], None, None, None)
        for col, x, last in zip(cols, p, rest, strict=True):
            x = np.asarray(x, dtype=np.float64)
            fill = np.zeros((x.shape[0], pad)) if last is None else np.repeat(last, pad, axis=1)
            col.append(np.broadcast_to(np.concatenate([x, fill], axis=1), (c, k_max)))
    return Pieces(*(np.stack(col, axis=1) for col in cols))
