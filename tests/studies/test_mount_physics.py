"""Isolators from their physics: air springs (stiffness n p A^2 / V with the pressure set by the load, the
orifice's Zener relaxation), elastomers' Maxwell ladders, mounts on their own axes, and bad input."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from isolab.engine import model, mount_laws
from isolab.engine.modal import modes
from isolab.studies.inputs.study import scene_batch, validate_scene

EXAMPLE = Path(__file__).parents[2] / "studies" / "examples" / "article-scriber.yaml"


def scriber() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def with_isolators(**blocks: object) -> dict:
    data = scriber()
    data["isolators"].update(copy.deepcopy(blocks))
    return data


AIR = {"effective_area": "0.03 m^2", "volume": "20 l", "reservoir_volume": "40 l"}


def test_air_spring_stiffness_is_n_p_a2_over_v_with_the_pressure_of_its_load() -> None:
    plain, _ = scene_batch(validate_scene(scriber()))
    batch, _ = scene_batch(validate_scene(with_isolators(air=AIR)))
    load = plain.iso_k[..., 2] / (2 * np.pi * 3.5) ** 2 * plain.g  # the preset's k = (W / g) (2 pi f)^2
    p = load / 0.03
    assert p == pytest.approx(mount_laws.air_pressure(load, 0.03))
    expected = 1.4 * (p + 101325.0) * 0.03**2 / 0.06
    assert np.allclose(batch.iso_k[..., 2], expected, rtol=1e-12)
    # horizontal axes and damping ratio stay the preset's: c scales with sqrt(k)
    assert np.array_equal(batch.iso_k[..., :2], plain.iso_k[..., :2])
    zeta = batch.iso_c[..., 2] / (2 * np.sqrt(batch.iso_k[..., 2] * load / plain.g))
    assert np.allclose(zeta, 0.10, rtol=1e-12)
    # a 25 kN mount on 300 cm^2: 8.3 bar gauge
    assert p.max() == pytest.approx(load.max() / 0.03)


def test_zener_loss_peak_from_a_frequency_sweep() -> None:
    """The orifice's standard linear solid: the loss factor of K(w), swept, peaks at
    ``k1 / (2 sqrt(k0 (k0 + k1)))`` at ``w = sqrt(k0 / (k0 + k1)) / tau``; the slow and fast limits are
    the stiffness of spring plus reservoir and of the spring alone."""
    p, A, V, Vr, n = 7e5, 0.03, 0.02, 0.04, 1.4
    R = mount_laws.orifice_resistance(2e-6, 0.05)
    k0, k1, tau = mount_laws.air_zener(p, A, V, Vr, R, n)
    assert k0 == pytest.approx(n * (p + 101325) * A * A / (V + Vr))
    assert k0 + k1 == pytest.approx(n * (p + 101325) * A * A / V)
    assert tau == pytest.approx(R * V * Vr / (n * (p + 101325) * (V + Vr)))
    eta_max, w_peak = mount_laws.zener_loss_peak(k0, k1, tau)
    w = np.geomspace(w_peak / 100, w_peak * 100, 400_001)
    K = mount_laws.complex_stiffness(k0, np.array([k1]), np.array([tau]), w)
    eta = K.imag / K.real
    i = int(np.argmax(eta))
    assert eta[i] == pytest.approx(eta_max, rel=1e-9)
    assert w[i] == pytest.approx(w_peak, rel=1e-4)
    assert eta_max == pytest.approx((3.0 - 1.0) / (2 * np.sqrt(3.0)))  # V_r = 2 V: fast / slow = 3
    assert K[0].real == pytest.approx(k0, rel=1e-3) and K[-1].real == pytest.approx(k0 + k1, rel=1e-3)


def test_orifice_sets_the_vertical_damping_at_the_mounts_own_frequency() -> None:
    air = dict(AIR, orifice={"area": "2 mm^2", "length": "50 mm"})
    batch, _ = scene_batch(validate_scene(with_isolators(air=air)))
    plain, _ = scene_batch(validate_scene(scriber()))
    load = plain.iso_k[..., 2] / (2 * np.pi * 3.5) ** 2 * plain.g
    for j in range(4):
        k0, k1, tau = mount_laws.air_zener(
            load[0, j] / 0.03, 0.03, 0.02, 0.04, mount_laws.orifice_resistance(2e-6, 0.05)
        )
        w = np.sqrt(batch.iso_k[0, j, 2] * plain.g / load[0, j])  # the frequency the equivalent is taken at
        K = mount_laws.complex_stiffness(k0, np.array([k1]), np.array([tau]), np.array([w]))[0]
        assert batch.iso_k[0, j, 2] == pytest.approx(K.real, rel=1e-9)
        assert batch.iso_c[0, j, 2] == pytest.approx(K.imag / w, rel=1e-9)
        assert k0 < batch.iso_k[0, j, 2] < k0 + k1


@pytest.mark.parametrize(("eta", "tolerance"), [(0.05, 0.02), (0.1, 0.03), (0.2, 0.10)])
def test_maxwell_ladder_keeps_its_loss_factor_over_a_decade(eta: float, tolerance: float) -> None:
    """Three branches fitted to a loss factor and the stiffening it implies over a decade (about
    10^(2 eta / pi)): the loss factor stays within ``tolerance`` (relative) of the target from 5 to
    50 Hz, and the storage stiffness rises by the stated ratio."""
    ratio = 10 ** (2 * eta / np.pi)
    k0, kb, tau = mount_laws.fit_ladder(eta, ratio, 5.0, 50.0, branches=3)
    w = 2 * np.pi * np.geomspace(5.0, 50.0, 500)
    K = mount_laws.complex_stiffness(k0, kb, tau, w)
    loss = K.imag / K.real
    assert np.abs(loss / eta - 1).max() < tolerance
    assert K[-1].real / K[0].real == pytest.approx(ratio, rel=0.02)
    assert (kb >= 0).all() and len(kb) == 3


def test_inclined_layout_from_the_scene_file_decouples_x_and_rocking() -> None:
    """Four listed mounts inclined about Y toward the c.g. by 30 deg, with 0.2 of their axial stiffness
    across, at the height where their elastic axes meet at the c.g.: X and rotation about Y decouple."""
    kq, kp, phi, a, b = 2e5, 1e6, np.radians(30.0), 1.1, 1.8
    kxx = kp * np.sin(phi) ** 2 + kq * np.cos(phi) ** 2
    h = a * (kp - kq) * np.sin(phi) * np.cos(phi) / kxx
    data = scriber()
    cg = np.array([1.3, 2.1, 0.17])
    mounts = []
    for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        mounts.append(
            {
                "position": [float(cg[0] + sx * a), float(cg[1] + sy * b), float(cg[2] - h)],
                "k": [kq, kq, kp],
                "c": [1e3, 1e3, 5e3],
                "orientation": {"about": "y", "angle": f"{-sx * 30} deg"},
            }
        )
    data["isolators"] = {"preset": "air", "list": mounts}
    data["stages"] = []
    data["simulation"]["gravity_stiffness"] = False
    batch, _ = scene_batch(validate_scene(data))
    assert batch.has_orientation
    K = model.stiffness_matrix(batch)
    assert abs(K[0, 0, 4]) < 1e-9 * K[0, 0, 0]
    f = modes(model.mass_matrix(batch), K, model.damping_matrix(batch)).frequency[0]
    f_x = np.sqrt(4 * kxx / batch.mass[0]) / (2 * np.pi)
    assert np.min(np.abs(f - f_x)) < 1e-9 * f_x
    # without the orientation, the same scene has no frame and the mounts stand on the floor's axes
    for mt in mounts:
        del mt["orientation"]
    upright, _ = scene_batch(validate_scene(data))
    assert not upright.has_orientation


def test_a_scene_without_the_new_blocks_builds_the_same_batch() -> None:
    batch, _ = scene_batch(validate_scene(scriber()))
    assert not batch.has_orientation
    assert np.array_equal(batch.iso_frame, np.broadcast_to(np.eye(3), batch.iso_frame.shape))


@pytest.mark.parametrize(
    ("air", "field"),
    [
        ({**AIR, "effective_area": "-0.03 m^2"}, "effective_area"),
        ({**AIR, "effective_area": 0}, "effective_area"),
        ({**AIR, "volume": "0 l"}, "volume"),
        ({**AIR, "volume": "-2 l"}, "volume"),
        ({**AIR, "reservoir_volume": "-1 l"}, "reservoir_volume"),
        ({**AIR, "max_pressure": "-3 bar"}, "max_pressure"),
        ({**AIR, "orifice": {"area": 0, "length": "5 mm"}}, "orifice.area"),
        ({**AIR, "orifice": {"area": "1 mm^2", "length": "-5 mm"}}, "orifice.length"),
        ({**AIR, "reservoir_volume": 0, "orifice": {"area": "1 mm^2", "length": "5 mm"}}, "orifice"),
        ({**AIR, "polytropic_exponent": 2.5}, "polytropic_exponent"),
    ],
)
def test_bad_air_springs_are_refused_naming_the_field(air: dict, field: str) -> None:
    with pytest.raises(ValidationError) as err:
        validate_scene(with_isolators(air=air))
    text = str(err.value)
    assert field.split(".")[-1] in text and "air" in text


def test_bad_orientations_are_refused_naming_the_field() -> None:
    with pytest.raises(ValidationError, match="orientation"):
        validate_scene(with_isolators(orientation={"about": "y"}))
    with pytest.raises(ValidationError, match="orientation.matrix"):
        validate_scene(with_isolators(orientation={"matrix": [[1, 0, 0], [0, 2, 0], [0, 0, 1]]}))
    with pytest.raises(ValidationError, match="about"):
        validate_scene(with_isolators(orientation={"about": "w", "angle": 0.1}))


def test_a_pressure_above_the_rating_names_the_air_block() -> None:
    with pytest.raises(
        ValidationError, match=r"isolators\.air: mount 0 needs 9.85 bar .* max_pressure of 6 bar"
    ):
        validate_scene(with_isolators(air={**AIR, "max_pressure": "6 bar"}))
    validate_scene(with_isolators(air={**AIR, "max_pressure": "10 bar"}))
