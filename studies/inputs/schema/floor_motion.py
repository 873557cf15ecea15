"""Motion of the floor under the isolators: a sine per axis or a recorded displacement (what the time
integration sees), and the floor's steady vibration as a spectrum per axis (VC level, one-third-octave
bands or a PSD)."""

from __future__ import annotations

from typing import Annotated, Any, Literal, get_args

import numpy as np
from pydantic import BeforeValidator, Field, ValidationError, field_validator, model_validator

from isolab.engine.results import AXES
from isolab.studies.inputs.schema.errors import error_messages
from isolab.studies.inputs.schema.fields import (
    MAX_RECORDED_SAMPLES,
    FloorDisplacement,
    InputModel,
    NonNegativeFrequency,
    PositiveTime,
    within,
)
from isolab.studies.questions.floor import MAX_BAND_VELOCITY, band_number, canonical_vc
from isolab.studies.units import Angle, DisplacementPSD, Frequency, Velocity, VelocityPSD


class SineFloor(InputModel):
    """Floor displacement amplitude_i sin(2 pi frequency_i t + phase_i) along each floor axis."""

    amplitude: tuple[FloorDisplacement, FloorDisplacement, FloorDisplacement] = Field(description="m")
    frequency: tuple[NonNegativeFrequency, NonNegativeFrequency, NonNegativeFrequency] = Field(
        description="Hz"
    )
    phase: tuple[Angle, Angle, Angle] = Field((0.0, 0.0, 0.0), description="rad")


class RecordedDisplacement(InputModel):
    """Sampled floor displacement per axis, m (an axis left out does not move)."""

    x: list[FloorDisplacement] | None = Field(None, max_length=MAX_RECORDED_SAMPLES)
    y: list[FloorDisplacement] | None = Field(None, max_length=MAX_RECORDED_SAMPLES)
    z: list[FloorDisplacement] | None = Field(None, max_length=MAX_RECORDED_SAMPLES)

    @model_validator(mode="after")
    def _equal_lengths(self) -> RecordedDisplacement:
        lengths = {a: len(getattr(self, a)) for a in AXES if getattr(self, a) is not None}
        if not lengths:
            raise ValueError("floor.recorded.displacement: give at least one of x, y, z")
        if len(set(lengths.values())) != 1:
            raise ValueError(f"floor.recorded.displacement: x, y, z must have equal lengths, got {lengths}")
        if next(iter(lengths.values())) < 2:
            raise ValueError("floor.recorded.displacement: needs at least 2 samples")
        return self

    def samples(self) -> np.ndarray:
        """(3, F) displacement, m."""
        n = next(len(getattr(self, a)) for a in AXES if getattr(self, a) is not None)
        return np.array([getattr(self, a) if getattr(self, a) is not None else np.zeros(n) for a in AXES])


class RecordedFloor(InputModel):
    dt: PositiveTime = Field(description="sample interval, s")
    displacement: RecordedDisplacement


BandVelocity = Annotated[
    Velocity,
    within(0.0, MAX_BAND_VELOCITY, "velocity", "a floor vibration in one band, not an earthquake"),
]
MAX_SPECTRUM_POINTS = 100_000
"""Most points of a floor PSD per axis."""


class SpectrumBands(InputModel):
    """One-third-octave RMS velocity of the floor by band centre (``{4 Hz: 20 um/s, 8 Hz: 10 um/s}``):
    bands between given ones are interpolated on log-log axes, bands outside them are zero
    (:mod:`studies.questions.floor`)."""

    bands: dict[Annotated[Frequency, Field(gt=0)], BandVelocity] = Field(
        min_length=1, description="band centre (Hz, nominal or exact) -> RMS velocity in that band, m/s"
    )

    @field_validator("bands")
    @classmethod
    def _centres(cls, value: dict[float, float]) -> dict[float, float]:
        seen: dict[int, float] = {}
        for f in value:
            n = band_number(f)  # ValueError naming the frequency
            if n in seen:
                raise ValueError(f"{f:g} Hz and {seen[n]:g} Hz are the same band")
            seen[n] = f
        return value


class SpectrumPSD(InputModel):
    """A one-sided power spectral density of the floor: ``frequency`` (Hz, increasing) with either
    ``displacement`` (m^2/Hz) or ``velocity`` ((m/s)^2/Hz) at each frequency."""

    frequency: list[Annotated[Frequency, Field(gt=0)]] = Field(
        min_length=2, max_length=MAX_SPECTRUM_POINTS, description="Hz, increasing"
    )
    displacement: list[Annotated[DisplacementPSD, Field(ge=0)]] | None = Field(
        None, max_length=MAX_SPECTRUM_POINTS, description="displacement PSD, m^2/Hz"
    )
    velocity: list[Annotated[VelocityPSD, Field(ge=0)]] | None = Field(
        None, max_length=MAX_SPECTRUM_POINTS, description="velocity PSD, (m/s)^2/Hz (m^2/s^2/Hz)"
    )

    @model_validator(mode="after")
    def _one_series(self) -> SpectrumPSD:
        values = self.displacement if self.displacement is not None else self.velocity
        if values is None or (self.displacement is not None and self.velocity is not None):
            raise ValueError("psd: give either displacement (m^2/Hz) or velocity ((m/s)^2/Hz)")
        if len(values) != len(self.frequency):
            raise ValueError(
                f"psd: {len(values)} PSD values for {len(self.frequency)} frequencies; give one per frequency"
            )
        if any(b <= a for a, b in zip(self.frequency, self.frequency[1:], strict=False)):
            raise ValueError("psd.frequency: must increase")
        return self


class PSDSpectrum(InputModel):
    psd: SpectrumPSD


def _axis_spectrum(value: Any) -> Any:
    """One axis of a floor spectrum: a VC level name, ``{bands: ...}`` or ``{psd: ...}``; errors name the
    reason (pydantic adds the axis)."""
    if value is None or isinstance(value, SpectrumBands | PSDSpectrum):
        return value
    if isinstance(value, str):
        return canonical_vc(value)
    if isinstance(value, dict) and len(value) == 1 and ("bands" in value or "psd" in value):
        kind = SpectrumBands if "bands" in value else PSDSpectrum
        try:
            return kind.model_validate(value)
        except ValidationError as err:
            raise ValueError("; ".join(error_messages(err))) from None
    raise ValueError(
        "give a VC level (such as 'VC-D'), {bands: {<centre>: <RMS velocity>, ...}} or "
        f"{{psd: {{frequency: [...], displacement: [...]}}}}, got {value!r}"
    )


AxisSpectrum = Annotated[str | SpectrumBands | PSDSpectrum | None, BeforeValidator(_axis_spectrum)]


class FloorSpectrum(InputModel):
    """The floor's steady vibration per axis as a spectrum (what ``floor_point_velocity`` is computed
    from; :mod:`studies.questions.floor`): per floor axis a VC level (``z: VC-D``), one-third-octave band
    levels
    (``z: {bands: {4 Hz: 20 um/s, ...}}``) or a PSD (``z: {psd: {frequency: [...], displacement:
    [...]}}``). An axis left out does not move; the axes are uncorrelated."""

    x: AxisSpectrum = None
    y: AxisSpectrum = None
    z: AxisSpectrum = None

    @model_validator(mode="after")
    def _some_axis(self) -> FloorSpectrum:
        if self.x is None and self.y is None and self.z is None:
            raise ValueError("floor.spectrum: give at least one of x, y, z")
        return self


class FloorWave(InputModel):
    """A floor wave crossing the site at ``speed`` along the horizontal ``direction``: the floor under a
    mount at ``r`` moves as the floor under the base's c.g. did ``(r - c.g.) . e / speed`` earlier."""

    speed: Annotated[Velocity, Field(gt=0)] = Field(description="m/s (very fast: the uniform floor)")
    direction: tuple[float, float] = Field((1.0, 0.0), description="along the floor's X and Y, any length")

    @field_validator("direction")
    @classmethod
    def _direction(cls, value: tuple[float, float]) -> tuple[float, float]:
        norm = float(np.hypot(*value))
        if not np.isfinite(norm) or norm == 0.0:
            raise ValueError("direction: give a non-zero horizontal direction [x, y]")
        return (value[0] / norm, value[1] / norm)


FloorCoherence = Literal["correlated", "uncorrelated", "worst_phase"]
"""How the floor motions under different mounts combine (:mod:`isolab.engine.frequency`)."""
FLOOR_COHERENCE: tuple[str, ...] = get_args(FloorCoherence)
"""The coherences a floor may state."""


class Floor(InputModel):
    """Motion of the floor under the isolators: a sine per axis or a recorded displacement (the time
    integration sees them), and/or a ``spectrum`` (steady state, one-third-octave bands: the velocity at
    the points of interest, :mod:`studies.questions.floor`): the same under every mount, or one spectrum
    per mount (``per_mount``), a travelling ``wave``, and the ``coherence`` between mounts."""

    sine: SineFloor | None = None
    recorded: RecordedFloor | None = None
    spectrum: FloorSpectrum | None = None
    per_mount: list[FloorSpectrum] | None = Field(
        None,
        min_length=1,
        description="one floor spectrum per mount, in the mounts' order (not with spectrum)",
    )
    wave: FloorWave | None = Field(None, description="the spectrum travels across the site (correlated)")
    coherence: FloorCoherence = Field(
        "correlated",
        description="between mounts: correlated (in phase, or delayed by the wave), uncorrelated (powers "
        "add) or worst_phase (per frequency, the phases that maximise the response: an upper bound)",
    )

    @model_validator(mode="after")
    def _one_kind(self) -> Floor:
        if self.sine is not None and self.recorded is not None:
            raise ValueError("floor: give either sine or recorded, not both")
        if self.sine is None and self.recorded is None and self.spectrum is None and self.per_mount is None:
            raise ValueError("floor: give sine, recorded, spectrum or per_mount")
        if self.spectrum is not None and self.per_mount is not None:
            raise ValueError("floor.per_mount: give either spectrum (every mount) or per_mount, not both")
        if self.wave is not None and self.coherence != "correlated":
            raise ValueError(
                f"floor.coherence: a travelling wave is a correlated floor, got coherence {self.coherence}"
            )
        mounts = self.per_mount is not None or self.wave is not None or self.coherence != "correlated"
        if mounts and self.spectrum is None and self.per_mount is None:
            raise ValueError("floor: wave and coherence shape a floor spectrum: give spectrum or per_mount")
        if mounts and (self.sine is not None or self.recorded is not None):
            raise ValueError(
                "floor: per_mount, wave and coherence act on the floor spectrum only; the time integration's "
                "sine or recorded floor moves uniformly: give them in separate scenes"
            )
        return self

    def check_mounts(self, n_mounts: int) -> None:
        """Refuse a ``per_mount`` list whose length is not the number of mounts (ValueError naming it)."""
        if self.per_mount is not None and len(self.per_mount) != n_mounts:
            raise ValueError(
                f"floor.per_mount: {len(self.per_mount)} spectra for {n_mounts} mounts (one per mount, in "
                "the mounts' order)"
            )
