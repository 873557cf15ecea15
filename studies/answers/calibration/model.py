"""The model a calibration fits: a scene's simulated channels on the measurement's times.

:class:`ChannelModel` runs the base case and its perturbed cases in one engine batch, turns the recorded
displacement into each channel's quantity (velocity and acceleration as central first and second
differences over +- ``dt``), interpolates it linearly onto the measurement's times shifted by the time
offset (at rest before the motion starts) and filters acceleration channels like the measurement
(detrended, zero-phase Butterworth band-pass). :func:`simulation_choice` sets the fidelity, integrator and
step it runs with; :func:`synthetic_measurement` uses it to make what sensors would record of a scene.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from isolab.engine import STATUS_NAMES, SceneError, simulate
from isolab.studies.answers.calibration.measurements import (
    AXIS_NAMES,
    LOCATION_CG,
    Measurement,
    parse_channel,
)
from isolab.studies.answers.calibration.parameters import BoundedParameter, to_si_loc
from isolab.studies.inputs.definitions import DefinitionError, Loc, detail
from isolab.studies.inputs.scenes import build_batch
from isolab.studies.inputs.schema import Scene
from isolab.studies.inputs.study import validate_scene


@dataclass
class SimulationChoice:
    """The fidelity, integrator and step (``dt``, s) the fit simulates with, and whether the engine's
    stability guard may shorten the step."""

    fidelity: str
    integrator: str
    dt: float
    auto_step: bool


class ChannelModel:
    """Simulated channels of a scene on the measurement's times, as the parameters and offset vary.

    Args:
        scene: the validated scene the parameters are written into.
        params: the fitted parameters (their targets are overridden per case).
        meas: the measurement whose times and channels are simulated.
        choice: the model and step the engine runs.
        offset_bounds: bounds of the time offset, s (the lower one sets how long the simulation runs).
        highpass: corner of the acceleration channels' high-pass filter, Hz (0: none).
        lowpass: corner of their low-pass filter, Hz (None: the default, 0: none).
        prefix: where the request's fields live, for error locations.
        check_signal: refuse a measured channel without usable signal.

    Raises:
        DefinitionError: filters the measurement cannot take, or a channel without signal.
    """

    def __init__(
        self,
        scene: Scene,
        params: list[BoundedParameter],
        meas: Measurement,
        choice: SimulationChoice,
        offset_bounds: tuple[float, float],
        highpass: float,
        lowpass: float | None,
        prefix: Loc,
        check_signal: bool = True,
    ):
        self.scene = scene
        self.params = params
        self.meas = meas
        self.choice = choice
        self.t = meas.time
        self.duration = max(float(meas.time[-1] - offset_bounds[0]) + 3 * choice.dt, 10 * choice.dt)
        self.points = list(scene.points)
        self.sos: np.ndarray | None = None
        self.highpass = 0.0
        self.lowpass = 0.0
        self.accel = [k for k, c in enumerate(meas.channels) if c.order == 2]
        self.gain = np.ones(len(meas.channels))
        self.profile = np.ones((meas.time.size, len(meas.channels)))
        """(N, ch) variance of each sample's filtered noise over a sample's in mid-record (1 unfiltered):
        near the ends of the record the band-pass's transients make it several times larger."""
        if self.accel:
            step = np.diff(self.t)
            fs = 1.0 / float(step.mean())
            lp = min(0.2 * fs, 0.03 / choice.dt) if lowpass is None else lowpass
            if lp >= 0.45 * fs:
                raise DefinitionError(
                    [detail([*prefix, "lowpass"], f"must be below half the sample rate ({fs / 2:g} Hz)")]
                )
            if highpass > 0 and lp > 0 and not highpass < lp:
                raise DefinitionError([detail([*prefix, "highpass"], f"must be below lowpass ({lp:g} Hz)")])
            if highpass >= 0.45 * fs:
                raise DefinitionError(
                    [detail([*prefix, "highpass"], f"must be below half the sample rate ({fs / 2:g} Hz)")]
                )
            if (highpass > 0 or lp > 0) and np.max(np.abs(step - step.mean())) > 0.01 * step.mean():
                raise DefinitionError(
                    [
                        detail(
                            [*prefix, "measurement", "time"],
                            "acceleration channels are filtered, which needs evenly spaced samples (within "
                            "1 %); resample them, or switch the filters off (highpass 0, lowpass 0)",
                        )
                    ]
                )
            from scipy.signal import butter  # on first use: importing scipy costs a command 0.4 s

            if highpass > 0 and lp > 0:
                self.sos = butter(2, [highpass, lp], btype="bandpass", fs=fs, output="sos")
            elif highpass > 0:
                self.sos = butter(2, highpass, btype="highpass", fs=fs, output="sos")
            elif lp > 0:
                self.sos = butter(2, lp, btype="lowpass", fs=fs, output="sos")
            self.highpass, self.lowpass = float(highpass), float(lp)
            if self.sos is not None:
                if self.t.size <= 3 * (2 * len(self.sos) + 1):
                    raise DefinitionError(
                        [
                            detail(
                                [*prefix, "measurement", "time"],
                                f"{self.t.size} samples are too few to filter the acceleration channels; "
                                "give more, or switch the filters off (highpass 0, lowpass 0)",
                            )
                        ]
                    )
                self.gain[self.accel] = _noise_gain(self.sos, self.t.size)
                self.profile[:, self.accel] = (
                    noise_profile(self.sos, self.t.size) / self.gain[self.accel[0]]
                )[:, None]
        self.cases = 0
        self.calls = 0
        self.watch: Callable[[int, int], None] | None = None
        """Called as ``watch(engine_calls, cases)`` before each engine batch (progress; it may raise to
        stop the fit)."""
        self.measured = self.filtered(np.stack([c.values for c in meas.channels], axis=1))
        rms = np.sqrt(np.mean(self.measured**2, axis=0))
        for k, c in enumerate(meas.channels if check_signal else []):
            if not (np.isfinite(rms[k]) and rms[k] > 1e-30 and rms[k] < 1e30):
                raise DefinitionError(
                    [
                        detail(
                            [*prefix, "measurement", "channels", k],
                            f"channel {c.name!r} has no usable signal (RMS {rms[k]:.3g} in SI"
                            + (", after the acceleration filters)" if c.order == 2 else ")"),
                        )
                    ]
                )

    def filtered(self, y: np.ndarray) -> np.ndarray:
        """(N, ch) with the acceleration channels detrended (a straight line fitted and removed: the
        sensor's bias and linear drift) and band-passed (zero phase)."""
        return self._filtered(y, self.accel)

    def _filtered(self, y: np.ndarray, accel: Sequence[int]) -> np.ndarray:
        """``y`` (N, m) with the columns ``accel`` detrended and band-passed, each on its own."""
        if self.sos is None:
            return y
        from scipy.signal import detrend, sosfiltfilt

        y = np.array(y, dtype=np.float64, copy=True)
        y[:, accel] = sosfiltfilt(self.sos, detrend(y[:, accel], axis=0), axis=0)
        return y

    def histories(self, values: np.ndarray) -> list[tuple[np.ndarray, np.ndarray] | None]:
        """Per row of ``values`` (SI parameter values, shape (k, P)), from ONE engine call: the engine's
        times (from one step before the motion) and each channel's quantity there (finite differences of
        the recorded displacement); None for a case that failed."""
        k = values.shape[0]
        if self.watch is not None:
            self.watch(self.calls, self.cases)
        overrides: dict[str, np.ndarray] = {"simulation.duration": np.full(k, self.duration)}
        for j, p in enumerate(self.params):
            for leaf in p.target.writes:
                overrides[leaf] = values[:, j]
        try:
            batch = build_batch([self.scene], overrides, n_cases=k)
        except ValueError:
            return [None] * k
        c = self.choice
        result = simulate(batch, c.fidelity, c.integrator, c.dt, auto_step=c.auto_step, record=list(range(k)))
        self.cases += k
        self.calls += 1
        h = result.history
        assert h is not None
        out: list[tuple[np.ndarray, np.ndarray] | None] = []
        for i in range(k):
            if STATUS_NAMES[int(result.status[i])] != "ok":
                out.append(None)
                continue
            n = int(h["n_samples"][i])
            t = np.asarray(h["time"][i, :n])
            cols = []
            for ch in self.meas.channels:
                a = AXIS_NAMES.index(ch.axis)
                if a >= 3:
                    cols.append(h["rotation"][i, :n, a - 3])
                elif ch.location == LOCATION_CG:
                    cols.append(h["displacement"][i, :n, a])
                else:
                    cols.append(h["point_displacement"][i, :n, self.points.index(ch.location), a])
            y = np.stack(cols, axis=1)
            if not np.all(np.isfinite(y)) or t.size < 3:
                out.append(None)
                continue
            dt = float(t[1] - t[0])
            # at rest before the motion: one sample of zeros at -dt, and the last sample held
            yp = np.concatenate([np.zeros((1, y.shape[1])), y, y[-1:]])
            q = np.empty((t.size + 1, y.shape[1]))
            q[0] = 0.0
            for kk, ch in enumerate(self.meas.channels):
                if ch.order == 0:
                    q[1:, kk] = y[:, kk]
                elif ch.order == 1:  # central difference: the mean velocity over +- dt
                    q[1:, kk] = (yp[2:, kk] - yp[:-2, kk]) / (2 * dt)
                else:  # second difference: the acceleration averaged over +- dt
                    q[1:, kk] = (yp[2:, kk] - 2 * yp[1:-1, kk] + yp[:-2, kk]) / dt**2
            out.append((np.concatenate([[-dt], t]), q))
        return out

    def sample(self, hist: tuple[np.ndarray, np.ndarray], offset: float) -> np.ndarray:
        """(N, ch) simulated channels at the measurement's times (interpolated linearly; zero before the
        motion starts), unfiltered."""
        tg, q = hist
        ts = self.t - offset
        out = np.empty((ts.size, q.shape[1]))
        for k in range(q.shape[1]):
            out[:, k] = np.interp(ts, tg, q[:, k], left=0.0, right=q[-1, k])
        return out

    def predict(self, hist: tuple[np.ndarray, np.ndarray], offset: float) -> np.ndarray:
        """(N, ch) simulated channels at the measurement's times, filtered like the measurement."""
        return self.filtered(self.sample(hist, offset))

    def predict_many(
        self, hist: tuple[np.ndarray, np.ndarray], offsets: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """(k, N, ch): :meth:`predict` at each of the ``offsets`` (k,), s, filtered side by side (each
        column detrended and filtered on its own: equal to its :meth:`predict` to round-off), one call of
        the filters per :data:`FILTER_BLOCK` values instead of one per offset."""
        offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
        n, nch = self.t.size, len(self.meas.channels)
        out = np.empty((offsets.size, n, nch))
        per = max(1, FILTER_BLOCK // max(n * nch, 1))  # offsets filtered together
        for a in range(0, offsets.size, per):
            block = offsets[a : a + per]
            side = np.concatenate([self.sample(hist, float(o)) for o in block], axis=1)  # (N, k ch)
            accel = [j * nch + k for j in range(block.size) for k in self.accel]
            side = self._filtered(side, accel)
            out[a : a + block.size] = side.reshape(n, block.size, nch).transpose(1, 0, 2)
        return out


FILTER_BLOCK = 1 << 21
"""Most values (samples x channels x offsets) :meth:`ChannelModel.predict_many` filters in one call (16 MB
per array of them)."""

PROFILE_PROBES = 48
"""Random probes of :func:`noise_profile` (its relative error per sample, after smoothing, is a few %)."""
PROFILE_SMOOTHING = 31
"""Samples of the moving average that smooths :func:`noise_profile`."""


def noise_profile(sos: np.ndarray, n: int) -> np.ndarray:
    """(n,) variance of each sample of white noise of unit variance after the acceleration channels'
    processing (a straight line removed, then the zero-phase filter ``sos``), estimated from random
    +-1 probes (fixed seed) and smoothed: about the noise gain in mid-record, larger at the ends."""
    from scipy.signal import detrend, sosfiltfilt

    rng = np.random.default_rng(0)
    acc = np.zeros(n)
    for _ in range(PROFILE_PROBES // 8):
        z = rng.choice([-1.0, 1.0], size=(n, 8))
        acc += np.sum(sosfiltfilt(sos, detrend(z, axis=0), axis=0) ** 2, axis=1)
    acc /= 8 * (PROFILE_PROBES // 8)
    w = min(PROFILE_SMOOTHING, n)
    padded = np.pad(acc, (w // 2, w - 1 - w // 2), mode="edge")
    return np.convolve(padded, np.ones(w) / w, mode="valid")


def _noise_gain(sos: np.ndarray, n: int) -> float:
    """Variance of white noise of unit variance after the zero-phase filter ``sos`` (sum of the squared
    impulse response): the fraction of a filtered channel's samples that count as independent."""
    from scipy.signal import sosfiltfilt

    m = min(n, 20_000)
    x = np.zeros(m)
    x[m // 2] = 1.0
    return float(np.clip(np.sum(sosfiltfilt(sos, x) ** 2), 1e-6, 1.0))


DEFAULT_DT = 1e-3
"""The step a calibration simulates with where neither the request nor the scene gives one, s."""
STEPS_PER_PERIOD = 20
"""Fewest engine steps per period of the scene's fastest mode a calibration simulates with."""


def check_step(scene: Scene, meas: Measurement, choice: SimulationChoice, prefix: Loc) -> None:
    """Refuse a step too coarse for the record (longer than its sample interval: the simulated traces
    would be straight lines between the measured samples) or for the model (fewer than
    :data:`STEPS_PER_PERIOD` steps per period of the scene's fastest mode).

    Raises:
        DefinitionError: at ``prefix + ["simulation", "dt"]``, naming the limit.
    """
    loc = [*prefix, "simulation", "dt"]
    interval = float(np.median(np.diff(meas.time)))
    if choice.dt > interval * (1 + 1e-9):
        raise DefinitionError(
            [
                detail(
                    loc,
                    f"{choice.dt:g} s is longer than the measurement's sample interval ({interval:g} s): "
                    f"take a step of at most {interval:g} s",
                )
            ]
        )
    from isolab.engine import modal
    from isolab.engine import model as engine_model

    batch = build_batch([scene])
    try:
        md = modal.modes(
            engine_model.mass_matrix(batch),
            engine_model.stiffness_matrix(batch),
            engine_model.damping_matrix(batch),
        )
    except np.linalg.LinAlgError:
        return
    f_max = float(np.nanmax(md.frequency)) if np.size(md.frequency) else 0.0
    if f_max > 0 and choice.dt > 1.0 / (STEPS_PER_PERIOD * f_max):
        limit = 1.0 / (STEPS_PER_PERIOD * f_max)
        raise DefinitionError(
            [
                detail(
                    loc,
                    f"{choice.dt:g} s is too coarse for the scene's fastest mode ({f_max:.3g} Hz): take a "
                    f"step of at most {limit:.3g} s ({STEPS_PER_PERIOD} steps per period)",
                )
            ]
        )


def simulation_choice(scene: Scene, simulation: Mapping[str, Any] | None, prefix: Loc) -> SimulationChoice:
    """The model the fit simulates with: the scene's simulation block, with ``simulation``'s fidelity,
    integrator, dt (s or text with units) and auto_step over it; ltv with rk4 at 1 ms where the scene has
    an accuracy request instead.

    Raises:
        DefinitionError: another field, a step that is not positive or a pair the engine refuses.
    """
    sim = scene.simulation
    data = {k: getattr(sim, k) for k in ("fidelity", "integrator", "dt", "auto_step")}
    for k, v in (simulation or {}).items():
        if k not in ("fidelity", "integrator", "dt", "auto_step"):
            raise DefinitionError(
                [
                    detail(
                        [*prefix, "simulation", k],
                        "a calibration chooses only fidelity, integrator, dt, auto_step",
                    )
                ]
            )
        data[k] = v
    if data["dt"] is not None:
        data["dt"] = to_si_loc(data["dt"], "time", [*prefix, "simulation", "dt"])
    if not isinstance(data["auto_step"], bool):
        raise DefinitionError(
            [
                detail(
                    [*prefix, "simulation", "auto_step"], f"must be true or false, got {data['auto_step']!r}"
                )
            ]
        )
    fidelity = data["fidelity"] or "ltv"
    integrator = data["integrator"] or ("exact" if fidelity == "lti" else "rk4")
    dt = DEFAULT_DT if data["dt"] is None else float(data["dt"])
    if not (math.isfinite(dt) and dt > 0):
        raise DefinitionError(
            [detail([*prefix, "simulation", "dt"], f"must be a positive step, got {dt:g} s")]
        )
    from isolab.engine import check_choice

    try:
        check_choice(fidelity, integrator)
    except SceneError as err:
        raise DefinitionError([detail([*prefix, "simulation", err.field], err.reason)]) from None
    return SimulationChoice(fidelity, integrator, dt, bool(data["auto_step"]))


def synthetic_measurement(
    scene: Mapping[str, Any] | Scene,
    channels: Sequence[tuple[str, str]],
    time: np.ndarray,
    offset: float = 0.0,
    noise: float = 0.0,
    bias: float = 0.0,
    drift: float = 0.0,
    seed: int = 0,
    simulation: Mapping[str, Any] | None = None,
) -> Measurement:
    """What sensors would record of ``scene``: each channel ``(name, unit)`` at ``time`` (s), the motion
    starting at ``offset`` on that clock, plus white noise of ``noise`` times the channel's RMS and, on
    acceleration channels, a bias (m/s^2 or rad/s^2) and a linear drift (per s). For tests and examples.
    """
    sc = scene if isinstance(scene, Scene) else validate_scene(dict(scene))
    t = np.asarray(time, dtype=np.float64)
    chans = [parse_channel(n, u, np.zeros(t.size), [n]) for n, u in channels]
    meas = Measurement(t, chans, "synthetic")
    choice = simulation_choice(sc, simulation, [])
    model = ChannelModel(sc, [], meas, choice, (offset, offset), 0.0, 0.0, [], check_signal=False)
    hist = model.histories(np.zeros((1, 0)))[0]
    if hist is None:
        raise ValueError("the scene does not simulate")
    clean = model.sample(hist, offset)
    rng = np.random.default_rng(seed)
    for k, ch in enumerate(chans):
        v = clean[:, k] + noise * float(np.sqrt(np.mean(clean[:, k] ** 2))) * rng.standard_normal(t.size)
        if ch.order == 2:
            v = v + bias + drift * (t - t[0])
        ch.values = v
    return meas
