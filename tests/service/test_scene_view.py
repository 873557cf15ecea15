"""What the service computes from a scene before it runs (``POST /scenes/check``) against closed forms: a
block's mass, inertia and c.g., mount loads and frequencies, mode shapes that are the base's rigid-body
modes; the example scenes; and the mode shapes ``POST /simulations`` carries."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient

from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.authoring.authoring import EXAMPLES_DIR

TOKEN = "s3cret"
G = 9.80665
DOFS = ("x", "y", "z", "rx", "ry", "rz")


@pytest.fixture
def bare(tmp_path: Path) -> TestClient:
    return TestClient(create_app(Settings(data_dir=tmp_path, api_token=TOKEN, max_cases=100)))


def auth() -> dict[str, str]:
    return {"Authorization": f"Bearer {TOKEN}"}


def block_scene(f_vertical: float = 4.0) -> dict:
    """A 2 x 3 x 0.5 m block of 2500 kg/m^3 (7.5 t) with its minimum corner at (1, 2, 0), on four mounts
    0.4 m below its c.g., no stage."""
    return {
        "machine": {
            "block": {"size": ["2 m", "3 m", "0.5 m"], "density": "2500 kg/m^3", "corner": [1, 2, 0]}
        },
        "isolators": {
            "preset": "air",
            "f_vertical": f"{f_vertical} Hz",
            "f_horizontal": "3 Hz",
            "layout": {"span_x": "1.6 m", "span_y": "2.4 m", "height": "0.4 m"},
        },
        "points": {"tool": [2, 3.5, 0.6]},
    }


def test_a_block_base_has_the_mass_inertia_and_cg_of_the_closed_form(bare: TestClient) -> None:
    r = bare.post("/scenes/check", json={"scene": block_scene()}, headers=auth())
    assert r.status_code == 200, r.text
    base = r.json()["base"]
    m = 2500.0 * 2 * 3 * 0.5
    assert base["source"] == "block" and base["mass"] == pytest.approx(m) and base["density"] == 2500.0
    inertia = np.array(base["inertia"])
    expected = m / 12 * np.diag([3**2 + 0.5**2, 2**2 + 0.5**2, 2**2 + 3**2])
    np.testing.assert_allclose(inertia, expected, rtol=1e-12, atol=1e-9)
    assert base["cg"] == pytest.approx([2.0, 3.5, 0.25])
    assert base["box_corner"] == [1.0, 2.0, 0.0] and base["box_size"] == [2.0, 3.0, 0.5]
    assert base["total_mass"] == pytest.approx(m)  # no stage


def test_mounts_carry_the_weight_at_their_frequency_and_the_modes_are_rigid_body_modes(
    bare: TestClient,
) -> None:
    view = bare.post("/scenes/check", json={"scene": block_scene()}, headers=auth()).json()
    m = 7500.0
    mounts = view["mounts"]
    assert [x["place"] for x in mounts] == ["front-left", "front-right", "back-right", "back-left"]
    assert mounts[0]["position"] == pytest.approx([1.2, 2.3, 0.25 - 0.4])
    for mount in mounts:  # the symmetric layout shares the weight equally
        assert mount["static_load"] == pytest.approx(m * G / 4, rel=1e-9)
        assert mount["f_vertical"] == pytest.approx(4.0, rel=1e-9)
        assert mount["f_horizontal"] == pytest.approx(3.0, rel=1e-9)
        kz = mount["stiffness"][2]
        assert kz == pytest.approx((2 * math.pi * 4.0) ** 2 * m / 4, rel=1e-9)
    modes = view["modes"]
    assert [md["mode"] for md in modes] == [1, 2, 3, 4, 5, 6]
    freqs = [md["frequency"] for md in modes]
    assert freqs == sorted(freqs)
    # the rigid block heaves on four vertical springs of m/4 (2 pi 4 Hz)^2 at exactly 4 Hz: no coupling
    heave = next(md for md in modes if md["name"] == "heave")
    assert heave["frequency"] == pytest.approx(4.0, rel=1e-9)
    assert heave["shape"]["z"] == pytest.approx(1.0)  # 1 m at the far mount, upwards
    assert max(abs(heave["shape"][k]) for k in DOFS if k != "z") < 1e-9
    # shapes are M-orthogonal: M = diag(m, m, m, Ixx, Iyy, Izz) of the bare block
    M = np.diag([m, m, m, *np.diag(np.array(view["base"]["inertia"]))])
    phi = np.array([[md["shape"][k] for k in DOFS] for md in modes])
    gram = phi @ M @ phi.T
    off = gram - np.diag(np.diag(gram))
    assert np.abs(off).max() < 1e-9 * np.abs(np.diag(gram)).max()
    # each scaled so the mount that moves most moves 1 m
    arms = np.array([x["position"] for x in mounts]) - np.array(view["base"]["cg"])
    for row in phi:
        moved = row[:3] + np.cross(row[3:], arms)
        assert np.linalg.norm(moved, axis=1).max() == pytest.approx(1.0)
    assert view["points"] == {"tool": [2.0, 3.5, 0.6]}
    assert yaml.safe_load(view["yaml"]) == block_scene()
    study = yaml.safe_load(view["study_yaml"])
    assert study["scene"] == block_scene()
    assert (
        bare.post("/studies/validate", json={"text": view["study_yaml"]}, headers=auth()).status_code == 200
    )


def test_a_base_given_by_mass_is_drawn_as_the_box_around_its_mounts(bare: TestClient) -> None:
    scene = block_scene()
    scene["machine"] = {"mass": 3000, "cg": [0, 0, 0.3], "inertia_diagonal": [800, 900, 1500]}
    base = bare.post("/scenes/check", json={"scene": scene}, headers=auth()).json()["base"]
    assert base["source"] == "given" and base["mass"] == 3000.0 and base["density"] is None
    assert np.diag(np.array(base["inertia"])).tolist() == [800.0, 900.0, 1500.0]
    # mounts at x = +-0.8, y = +-1.2, z = -0.1: the box 10 % wider, from their top to twice the c.g.'s height
    assert base["box_corner"] == pytest.approx([-0.96, -1.44, -0.1])
    assert base["box_size"] == pytest.approx([1.92, 2.88, 0.8])


def test_the_scriber_s_stages_travel_and_a_bad_field_is_refused_as_a_run_refuses_it(bare: TestClient) -> None:
    scene = bare.get("/scenes/examples/article-scriber", headers=auth()).json()["scene"]
    assert scene == yaml.safe_load((EXAMPLES_DIR / "article-scriber.yaml").read_text(encoding="utf-8"))
    view = bare.post("/scenes/check", json={"scene": scene}, headers=auth()).json()
    assert view["base"]["mass"] == pytest.approx(2.6 * 4.2 * 0.34 * 2700)
    assert view["base"]["total_mass"] == pytest.approx(2.6 * 4.2 * 0.34 * 2700 + 1100)
    y, x = view["stages"]
    assert y["travel"] == pytest.approx([0.0, 3.0]) and y["travel_ends"][1] == pytest.approx([1.3, 3.6, 0.47])
    assert x["parent"] == "y" and x["travel"] == pytest.approx([0.0, 0.3])
    scene["stages"][0]["mass"] = "-3 kg"
    checked = bare.post("/scenes/check", json={"scene": scene}, headers=auth())
    run = bare.post("/simulations", json={"scene": scene}, headers=auth())
    assert checked.status_code == run.status_code == 422
    assert checked.json()["detail"] == run.json()["detail"]
    assert checked.json()["detail"][0]["loc"] == ["body", "scene", "stages", 0, "mass"]
    assert bare.post("/scenes/check", json={"scene": scene}).status_code == 401


def test_the_example_scenes(bare: TestClient) -> None:
    names = bare.get("/scenes/examples", headers=auth()).json()["names"]
    assert "article-scriber" in names and "isolator-comparison" in names  # a scene file and a study
    scene = bare.get("/scenes/examples/isolator-comparison", headers=auth()).json()["scene"]
    assert "machine" in scene and "isolators" in scene
    # a study's own floor and criteria come with its scene, as when it runs
    scene = bare.get("/scenes/examples/scriber-criteria", headers=auth()).json()["scene"]
    assert scene["criteria"]["tool"] == {"settle": {"within": "10 um", "after": "1 s"}, "velocity": "VC-C"}
    assert scene["floor"]["spectrum"]["z"]["bands"]["16 Hz"] == "30 um/s"
    assert bare.post("/scenes/check", json={"scene": scene}, headers=auth()).status_code == 200
    scene["criteria"]["tool"]["velocity"] = "VC-Q"
    refused = bare.post("/scenes/check", json={"scene": scene}, headers=auth())
    assert refused.status_code == 422
    assert refused.json()["detail"][0]["loc"] == ["body", "scene", "criteria", "tool", "velocity"]
    r = bare.get("/scenes/examples/no-such-example", headers=auth())
    assert r.status_code == 404 and "article-scriber" in r.json()["detail"]


def test_a_run_carries_the_shape_of_each_mode(bare: TestClient) -> None:
    view = bare.post("/scenes/check", json={"scene": block_scene()}, headers=auth()).json()
    answer = bare.post("/simulations", json={"scene": block_scene()}, headers=auth()).json()
    assert [md["frequency"] for md in answer["modes"]] == [md["frequency"] for md in view["modes"]]
    for ran, checked in zip(answer["modes"], view["modes"], strict=True):
        assert ran["name"] == checked["name"]
        assert [ran["shape"][k] for k in DOFS] == pytest.approx(
            [checked["shape"][k] for k in DOFS], abs=1e-12
        )


def test_each_stage_s_profile_is_sampled_as_its_closed_form(bare: TestClient) -> None:
    scene = bare.get("/scenes/examples/article-scriber", headers=auth()).json()["scene"]
    scene["stages"].append(
        {
            "name": "z",
            "mass": "20 kg",
            "home": [1.3, 2.0, 0.6],
            "axis": [0, 0, 1],
            "profile": {
                "type": "sequence",
                "start": "0.5 s",
                "segments": [
                    {"move": "0.1 m", "velocity": "0.5 m/s", "acceleration": "5 m/s^2"},
                    {"dwell": "0.4 s"},
                    {"move": "-0.04 m", "velocity": "0.5 m/s", "acceleration": "5 m/s^2"},
                ],
            },
        }
    )
    y, x, z = (
        s["profile"]
        for s in bare.post("/scenes/check", json={"scene": scene}, headers=auth()).json()["stages"]
    )
    # the X stage's trapezoid: 0.3 m at 1 m/s and 1 g from 1.65 s, ends at start + travel/v + v/a
    g = 9.80665
    assert x["end"] == pytest.approx(1.65 + 0.3 / 1.0 + 1.0 / g, rel=1e-12)
    t, s, v, a = (np.array(x[k]) for k in ("time", "position", "velocity", "acceleration"))
    assert t[0] == 0.0 and np.all(np.diff(t) > 0) and len(t) >= 600
    assert s[t < 1.65].max() == 0.0 and s[-1] == pytest.approx(0.3) and v.max() == pytest.approx(1.0)
    assert set(np.round(np.unique(a), 9)) <= {-g, 0.0, g} and a.max() == pytest.approx(g)
    assert np.abs(np.gradient(s, t) - v)[np.abs(a) == 0].max() < 1e-6  # velocity is the slope of position
    # the Y scan: out 3 m at 2 m/s and 2 g, dwell, back home
    assert max(y["position"]) == pytest.approx(3.0) and y["position"][-1] == pytest.approx(0.0, abs=1e-12)
    assert min(y["acceleration"]) == pytest.approx(-2 * g)
    # the sequence: up 0.1 m, 0.4 s still, down 0.04 m: ends at 0.06 m
    zs, zt = np.array(z["position"]), np.array(z["time"])
    assert zs.max() == pytest.approx(0.1) and zs[-1] == pytest.approx(0.06) and zs[zt < 0.5].max() == 0.0
    move = 0.1 / 0.5 + 0.5 / 5  # trapezoid of 0.1 m at 0.5 m/s, 5 m/s^2
    triangle = 2 * math.sqrt(0.04 / 5)  # too short to reach 0.5 m/s: a triangle
    assert z["end"] == pytest.approx(0.5 + move + 0.4 + triangle)
    assert -min(z["velocity"]) == pytest.approx(5 * triangle / 2, rel=1e-3)
