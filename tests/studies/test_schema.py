"""Scene and study inputs: units, presets, load share, validation errors that name their field."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from isolab.studies.inputs.isolators import PRESETS, damping_from_ratio, load_share, stiffness_from_frequency
from isolab.studies.inputs.parameters import resolve
from isolab.studies.inputs.schema import Scene, error_messages
from isolab.studies.inputs.study import Study, load_scene, load_study, validate_scene, validate_study
from isolab.studies.units import to_si

EXAMPLES = Path(__file__).resolve().parents[2] / "studies" / "examples"
G = 9.80665


def base_scene() -> dict:
    return yaml.safe_load((EXAMPLES / "article-scriber.yaml").read_text())


def errors(data: dict, model=Scene) -> list[str]:
    """The messages of validating ``data`` as ``model`` through parse and check, as users submit it."""
    validate = {Scene: validate_scene, Study: validate_study}[model]
    with pytest.raises(ValidationError) as info:
        validate(data)
    return error_messages(info.value)


def direct_machine(**kw) -> dict:
    return {"mass": 10000.0, "cg": [1.3, 2.1, 0.17], "inertia_diagonal": [1.5e4, 6e3, 2e4], **kw}


# ---------------------------------------------------------------------------------------------------------
# units


@pytest.mark.parametrize(
    ("text", "dimension", "si"),
    [
        ("2 g", "acceleration", 2 * G),
        ("0.5 gn", "acceleration", 0.5 * G),
        ("9.81 m/s^2", "acceleration", 9.81),
        ("3.5 Hz", "frequency", 3.5),
        ("20 rad/s", "frequency", 20 / (2 * math.pi)),
        ("1.2e6 N/m", "stiffness", 1.2e6),
        ("2e4 N s/m", "damping", 2e4),
        ("800 mm", "length", 0.8),
        ("10 um", "length", 10e-6),
        ("2 m/s", "velocity", 2.0),
        ("1000 kg", "mass", 1000.0),
        ("2 g", "mass", 0.002),
        ("2700 kg/m^3", "density", 2700.0),
        ("5 %", "dimensionless", 0.05),
        ("3 mrad", "angle", 0.003),
        ("200 ms", "time", 0.2),
        ("1e4 kg m^2", "inertia", 1e4),
        ("1.5e6", "stiffness", 1.5e6),
        (0.25, "length", 0.25),
        (3, "mass", 3.0),
    ],
)
def test_units_parse_to_si(text, dimension, si):
    assert to_si(text, dimension, "f") == pytest.approx(si, rel=1e-12)


def test_two_g_is_standard_gravity():
    assert to_si("2 g", "acceleration", "a") == pytest.approx(19.6133, abs=1e-12)


@pytest.mark.parametrize(
    ("value", "dimension", "reason"),
    [
        ("2 g", "length", "expected a length"),
        ("3.5 Hz", "stiffness", "expected a stiffness"),
        ("800 mm", "mass", "expected a mass"),
        ("3 mrad", "dimensionless", "angle"),
        ("nan", "length", "finite"),
        (float("nan"), "length", "finite"),
        ("inf m", "length", "finite"),
        ("two metres", "length", "cannot read"),
        (True, "length", "boolean"),
        ([1.0], "length", "expected a length"),
        ("", "length", "empty"),
        # text whose exact integer arithmetic would run for hours, or that no float holds: refused by the
        # units layer itself (a study file read by the CLI is screened as a REST body is)
        ("9**9**9 kg", "mass", "raised to a power again"),
        ("10**999 kg", "mass", "larger than 12"),
        ("(10)**6 kg", "mass", "must follow a number or a unit"),
        ("kg " + "m " * 200, "mass", "longer than 256"),
        ("1e300*1e300 kg", "mass", "finite"),
        ("999999999999**12*999999999999**12*999999999999**12 kg", "mass", "64-bit float"),
        # a word and a digit holds no number (the screen does not build the parser for it): no unit either
        ("Qpc9", "length", "cannot read"),
        ("km2", "length", "cannot read"),
    ],
)
def test_units_reject_with_field_and_reason(value, dimension, reason):
    with pytest.raises(ValueError) as info:
        to_si(value, dimension, "stages[0].mass")
    assert str(info.value).startswith("stages[0].mass: ")
    assert reason in str(info.value)


def test_a_scene_file_is_checked_without_building_the_units_parser() -> None:
    """The example scene (its integrator ``rk4`` a word and a digit, its quantities in common units) is
    screened and checked in a fresh process without importing pint (half a second of every command)."""
    code = (
        "import sys; from isolab.studies.inputs.file_checks import check_scene_file; "
        f"check_scene_file({str(EXAMPLES / 'article-scriber.yaml')!r}); print('pint' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.strip() == "False", out.stderr


def test_schema_fields_accept_units_and_numbers_alike():
    a, b = base_scene(), base_scene()
    b["machine"]["block"]["size"] = [2600, 4200, 340]  # wrong on purpose: plain numbers are SI (m)
    a_model = Scene.model_validate(a)
    assert a_model.stages[0].profile.acceleration == pytest.approx(2 * G)
    assert a_model.machine.block.size == (2.6, 4.2, 0.34)
    b["machine"]["block"]["size"] = ["2600 mm", "420 cm", 0.34]
    assert Scene.model_validate(b).machine.block.size == pytest.approx((2.6, 4.2, 0.34))


# ---------------------------------------------------------------------------------------------------------
# isolators: presets, load share


def test_presets_are_the_typical_vendor_figures():
    assert (PRESETS["active"].f_vertical, PRESETS["air"].f_vertical, PRESETS["elastomer"].f_vertical) == (
        1,
        3,
        10,
    )
    assert PRESETS["active"].skyhook and not PRESETS["air"].skyhook and not PRESETS["elastomer"].skyhook
    assert (PRESETS["active"].zeta, PRESETS["air"].zeta, PRESETS["elastomer"].zeta) == (0.4, 0.10, 0.05)


def test_load_share_symmetric_layout_is_a_quarter_each():
    xy = np.array([[-1.1, -1.8], [1.1, -1.8], [1.1, 1.8], [-1.1, 1.8]]) + [5.0, 7.0]
    f = load_share(xy, [5.0, 7.0], 98066.5)
    np.testing.assert_allclose(f, 98066.5 / 4, rtol=1e-12)


def test_load_share_balances_force_and_moments_off_centre():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-2, 2, size=(6, 2))
    c = np.array([0.3, -0.2])
    w = 12345.0
    f = load_share(xy, c, w)
    assert f.sum() == pytest.approx(w, rel=1e-12)
    np.testing.assert_allclose(f @ xy, w * c, rtol=1e-10, atol=1e-8)
    # least norm: the loads are an affine function of the mount position (equal springs under a rigid base)
    coef, *_ = np.linalg.lstsq(np.c_[np.ones(6), xy], f, rcond=None)
    np.testing.assert_allclose(np.c_[np.ones(6), xy] @ coef, f, rtol=1e-10)


def test_load_share_exact_for_three_mounts_and_vectorised():
    xy = np.array([[[0, 0], [2, 0], [0, 1]], [[0, 0], [4, 0], [1, 3]]], dtype=float)
    c = np.array([[0.5, 0.25], [1.0, 1.0]])
    w = np.array([100.0, 300.0])
    f = load_share(xy, c, w)
    for i in range(2):
        a = np.vstack([np.ones(3), xy[i, :, 0], xy[i, :, 1]])
        np.testing.assert_allclose(f[i], np.linalg.solve(a, w[i] * np.array([1, *c[i]])), rtol=1e-12)


def test_load_share_collinear_mounts_raise():
    with pytest.raises(ValueError, match="isolators: all on one line"):
        load_share([[0, 0], [1, 1], [3, 3], [-2, -2]], [0.5, 0.5], 1000.0)


def test_stiffness_and_damping_from_vendor_figures():
    load = 25000.0  # N, about 2549 kg
    k = stiffness_from_frequency(load, 3.0)
    assert math.sqrt(k / (load / G)) / (2 * math.pi) == pytest.approx(3.0, rel=1e-12)
    c = damping_from_ratio(k, load, 0.1)
    assert c / (2 * math.sqrt(k * load / G)) == pytest.approx(0.1, rel=1e-12)


# ---------------------------------------------------------------------------------------------------------
# machine


def test_block_mass_inertia_and_cg_closed_form():
    m = Scene.model_validate(base_scene()).machine
    mass, inertia, cg = m.properties()
    lx, ly, lz = 2.6, 4.2, 0.34
    assert mass == pytest.approx(2700 * lx * ly * lz, rel=1e-12)
    np.testing.assert_allclose(
        np.diag(inertia),
        [mass * (ly**2 + lz**2) / 12, mass * (lx**2 + lz**2) / 12, mass * (lx**2 + ly**2) / 12],
    )
    assert np.count_nonzero(inertia - np.diag(np.diag(inertia))) == 0
    np.testing.assert_allclose(cg, [1.3, 2.1, 0.17])
    assert 10_000 < mass < 10_100  # the article's 10 t base


def test_full_inertia_with_products_is_accepted():
    d = base_scene()
    d["machine"] = {
        "mass": 1e4,
        "cg": [1.3, 2.1, 0.17],
        "inertia": [[1.5e4, 800, 0], [800, 6e3, -200], [0, -200, 2e4]],
    }
    _, inertia, _ = Scene.model_validate(d).machine.properties()
    assert inertia[0, 1] == 800 and inertia[1, 2] == -200


# ---------------------------------------------------------------------------------------------------------
# validation errors name the field


def test_missing_machine():
    d = base_scene()
    del d["machine"]
    assert any(m.startswith("machine: Field required") for m in errors(d))


@pytest.mark.parametrize("mass", [-5.0, 0.0, "-5 kg"])
def test_negative_mass(mass):
    d = base_scene()
    d["machine"] = direct_machine(mass=mass)
    assert any(m.startswith("machine.mass: ") and "greater than 0" in m for m in errors(d))


@pytest.mark.parametrize("bad", ["nan", float("nan"), float("inf"), "NaN kg"])
def test_nan_and_inf_rejected(bad):
    d = base_scene()
    d["machine"] = direct_machine(mass=bad)
    assert any(m.startswith("machine.mass: ") and "finite" in m for m in errors(d))
    d = base_scene()
    d["stages"][0]["profile"]["velocity"] = bad
    assert any(m.startswith("stages.0.profile.scan.velocity") for m in errors(d))


def test_non_spd_inertia():
    d = base_scene()
    d["machine"] = direct_machine()
    del d["machine"]["inertia_diagonal"]
    d["machine"]["inertia"] = [[1e4, 2e4, 0], [2e4, 1e4, 0], [0, 0, 2e4]]
    msgs = errors(d)
    assert any(m.startswith("machine.inertia: must be positive definite") for m in msgs), msgs
    d["machine"]["inertia"] = [[1e4, 2e3, 0], [0, 1e4, 0], [0, 0, 2e4]]
    assert any(m.startswith("machine.inertia: must be symmetric") for m in errors(d))


def test_principal_moments_triangle_inequality():
    d = base_scene()
    d["machine"] = direct_machine(inertia_diagonal=[1e3, 1e3, 5e3])
    assert any(m.startswith("machine.inertia_diagonal: ") and "triangle" in m for m in errors(d))


def test_two_isolators():
    d = base_scene()
    d["isolators"] = {"preset": "air", "list": [{"position": [0, 0, 0]}, {"position": [2, 4, 0]}]}
    assert any(m.startswith("isolators: at least 3") for m in errors(d))


def test_collinear_isolators():
    d = base_scene()
    d["isolators"] = {"list": [{"position": [0, 0, 0]}, {"position": [1, 2, 0]}, {"position": [2, 4, 0]}]}
    assert any(m.startswith("isolators: all on one line") for m in errors(d))


def test_unknown_preset_and_typo():
    d = base_scene()
    d["isolators"]["preset"] = "rubber"
    assert any(m.startswith("isolators.preset: ") for m in errors(d))
    d = base_scene()
    d["isolators"]["layout"]["spanx"] = 2.0
    assert any(m.startswith("isolators.layout.spanx: Extra inputs") for m in errors(d))


def test_stage_parent_unknown_self_and_cycle():
    d = base_scene()
    d["stages"][1]["parent"] = "z"
    assert any(m.startswith("stages[1].parent: no stage named 'z'") for m in errors(d))
    d = base_scene()
    d["stages"][0]["parent"] = "y"
    assert any(m.startswith("stages[0].parent: ") and "itself" in m for m in errors(d))
    d = base_scene()
    d["stages"][0]["parent"] = "x"  # y rides on x, x rides on y
    assert any(m.startswith("stages[0].parent: cycle y -> x -> y") for m in errors(d))


def test_travel_too_long():
    d = base_scene()
    d["stages"][0]["profile"]["travel"] = "4.5 m"  # the base is 4.2 m long in Y
    msgs = errors(d)
    assert any(m.startswith("stages[0].profile.travel: ") and "4.2 m" in m for m in msgs), msgs
    d["stages"][0]["profile"]["travel"] = "-4 m"
    Scene.model_validate(d)  # within the base


def test_travel_bound_without_a_block():
    d = base_scene()
    d["machine"] = direct_machine()
    d["stages"][0]["profile"]["travel"] = 25.0
    assert any(m.startswith("stages[0].profile.travel: ") and "20 m" in m for m in errors(d))


def test_exact_integrator_needs_lti():
    d = base_scene()
    d["simulation"] = {"fidelity": "ltv", "integrator": "exact"}
    assert any(m.startswith("simulation.integrator: ") for m in errors(d))
    d["simulation"] = {"fidelity": "nonlinear", "integrator": "exact"}
    assert any(m.startswith("simulation.integrator: ") for m in errors(d))
    d["simulation"] = {"fidelity": "lti", "integrator": "exact"}
    assert Scene.model_validate(d).simulation.integrator == "exact"


def test_zero_axis_and_duplicate_stage():
    d = base_scene()
    d["stages"][1]["axis"] = [0, 0, 0]
    assert any(m.startswith("stages.1.axis: ") for m in errors(d))
    d = base_scene()
    d["stages"][1]["axis"] = [3, 4, 0]
    assert Scene.model_validate(d).stages[1].axis == pytest.approx((0.6, 0.8, 0.0))
    d["stages"][1]["name"] = "y"
    assert any(m.startswith("stages[1].name: ") for m in errors(d))


def test_mount_that_would_carry_no_load():
    d = base_scene()
    d["isolators"]["layout"]["span_y"] = 0.2  # the Y stage at home hangs 1.5 m off the mounts' centre
    assert any(m.startswith("isolators: isolator ") and "not positive" in m for m in errors(d))


def test_floor_needs_one_kind_and_equal_samples():
    d = base_scene()
    d["floor"] = {}
    assert any(m.startswith("floor: ") for m in errors(d))
    d["floor"] = {"recorded": {"dt": "1 ms", "displacement": {"x": [0, 1e-6, 0], "z": [0, 1e-6]}}}
    assert any("equal lengths" in m for m in errors(d))


# ---------------------------------------------------------------------------------------------------------
# studies


def study(**kw) -> dict:
    return {"name": "t", "scene": base_scene(), **kw}


def test_unknown_parameter_path_lists_what_exists():
    msgs = errors(study(parameters=[{"path": "stages.z.mass", "values": [1, 2]}]), Study)
    assert msgs[0].startswith("parameters[0].path: 'stages.z.mass' does not exist")
    assert "stages.y.mass" in msgs[0] and "isolators.layout.span_x" in msgs[0]
    msgs = errors(study(parameters=[{"path": "stages.x.profile.jerk", "values": [100]}]), Study)
    assert msgs[0].startswith("parameters[0].path: ")  # a trapezoid has no jerk


def test_parameter_values_checked_against_the_scene():
    msgs = errors(study(parameters=[{"path": "stages.y.mass", "values": ["1000 kg", -2]}]), Study)
    assert msgs[0].startswith("parameters[0] (stage_y_mass): the value -2 kg") and "stages.0.mass" in msgs[0]
    msgs = errors(study(parameters=[{"path": "isolators.preset", "values": ["air", "foam"]}]), Study)
    assert msgs[0].startswith("parameters[0].values[1]: 'foam'")
    msgs = errors(
        study(parameters=[{"path": "stages.y.profile.travel", "range": {"start": 1, "stop": 5, "num": 3}}]),
        Study,
    )
    assert "stages[0].profile.travel" in msgs[0]


def test_a_scene_input_is_varied_once():
    params = [{"path": "isolators.k.horizontal", "values": [1e5]}, {"path": "isolators.k.y", "values": [2e5]}]
    msg = errors(study(parameters=params), Study)[0]
    assert msg.startswith("parameters[1].path: 'isolators.k.y' sets what")


def test_default_names_units_and_paths():
    s = Scene.model_validate(base_scene())
    cases = {
        "isolators.preset": ("isolator_type", "", ("isolators.preset",)),
        "stages.y.profile.acceleration": (
            "stage_y_acceleration",
            "m/s^2",
            ("stages.y.profile.acceleration",),
        ),
        "stages.y.home.z": ("stage_y_home_z", "m", ("stages.y.home.2",)),
        "isolators.k.horizontal": ("isolator_k_horizontal", "N/m", ("isolators.k.x", "isolators.k.y")),
        "isolators.c.vertical": ("isolator_c_vertical", "N s/m", ("isolators.c.z",)),
        "isolators.layout.span_y": ("isolator_span_y", "m", ("isolators.layout.span_y",)),
        "isolators.f_vertical": ("isolator_f_vertical", "Hz", ("isolators.f_vertical",)),
        "isolators.zeta": ("isolator_zeta", "", ("isolators.zeta",)),
        "machine.block.size.y": ("machine_size_y", "m", ("machine.block.size.1",)),
        "points.tool.z": ("point_tool_z", "m", ("points.tool.2",)),
        "simulation.duration": ("duration", "s", ("simulation.duration",)),
    }
    for path, (name, unit, writes) in cases.items():
        t = resolve(path, s)
        assert (t.name, t.unit, t.writes) == (name, unit, writes), path
    assert resolve("isolators.preset", s).categorical


def test_design_needs_what_it_draws_from():
    msgs = errors(
        study(
            parameters=[{"path": "stages.y.mass", "range": {"start": 1, "stop": 2}}], design={"type": "lhs"}
        ),
        Study,
    )
    assert msgs[0].startswith("design.samples: ")
    msgs = errors(study(parameters=[{"path": "stages.y.mass", "range": {"start": 500, "stop": 900}}]), Study)
    assert "grid needs values, or a range with num" in msgs[0]
    msgs = errors(
        study(
            parameters=[{"path": "isolators.preset", "range": {"start": 1, "stop": 2}}],
            design={"type": "random", "samples": 4},
        ),
        Study,
    )
    assert msgs[0].startswith("parameters[0].range: ")
    msgs = errors(
        study(
            parameters=[{"path": "stages.y.mass"}, {"path": "stages.x.mass"}],
            design={"type": "list", "cases": [{"stage_y_mass": 900}]},
        ),
        Study,
    )
    assert msgs[0].startswith("design.cases[0]: missing stage_x_mass")


def test_study_simulation_overrides_the_scene_block_field_by_field():
    s = Study.model_validate(study(simulation={"fidelity": "lti", "integrator": "exact", "duration": "3 s"}))
    assert (s.simulation.fidelity, s.simulation.integrator, s.simulation.duration) == ("lti", "exact", 3.0)
    assert s.simulation.dt == 1e-3 and s.simulation.settle_tolerance == 10e-6
    msgs = errors(study(simulation={"integrator": "exact"}), Study)  # the scene's fidelity is ltv
    assert "simulation.integrator" in msgs[0]


def test_scene_file_is_read_only_by_load_study(tmp_path):
    data = {"name": "t", "scene_file": "article-scriber.yaml", "parameters": []}
    msgs = errors(data, Study)  # the web service validates bodies this way: no file is read
    assert msgs[0].startswith("scene: missing")
    s = load_study(data, base_dir=EXAMPLES)
    assert s.scene.stages[0].name == "y" and s.n_cases == 1
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "s.yaml").write_text((EXAMPLES / "article-scriber.yaml").read_text())
    study_file = tmp_path / "study.json"
    study_file.write_text(
        json.dumps(
            {
                "name": "j",
                "scene_file": "scenes/s.yaml",
                "parameters": [{"path": "stages.y.mass", "values": [500, "1 t"]}],
            }
        )
    )
    s = load_study(study_file)
    np.testing.assert_allclose(s.design().values["stage_y_mass"], [500.0, 1000.0])
    with pytest.raises(FileNotFoundError, match="scene_file"):
        load_study({"name": "t", "scene_file": "nowhere.yaml"}, base_dir=tmp_path)
    # a stored definition keeps both: the inline scene wins and no file is read
    inline = base_scene()
    inline["stages"][0]["mass"] = 1234.0
    s = load_study({"name": "t", "scene_file": "nowhere.yaml", "scene": inline}, base_dir=tmp_path)
    assert s.scene.stages[0].mass == 1234.0
    # YAML text, scene_file relative to base_dir
    text = "name: text\nscene_file: scenes/s.yaml\nparameters:\n  - {path: isolators.preset, values: [air]}\n"
    assert load_study(text, base_dir=tmp_path).design().values["isolator_type"].tolist() == ["air"]


def test_examples_load():
    scene = load_scene(EXAMPLES / "article-scriber.yaml")
    assert [s.name for s in scene.stages] == ["y", "x"] and scene.stages[1].parent == "y"
    assert scene.stages[0].profile.type == "scan" and scene.stages[0].profile.travel == 3.0
    assert scene.stages[1].home == scene.points["tool"]
    # the X move starts during the Y dwell: after the out-move (3/2 + 2/(2 g) s), before it returns
    out_end = 3.0 / 2.0 + 2.0 / (2 * G)
    assert out_end < scene.stages[1].profile.start < out_end + 0.2
    comp = load_study(EXAMPLES / "isolator-comparison.yaml")
    d = comp.design()
    assert d.kind == "grid" and d.shape == (3, 4) and d.names == ["isolator_type", "stage_y_acceleration"]
    np.testing.assert_allclose(d.levels["stage_y_acceleration"], np.linspace(0.5, 2.0, 4) * G)
    lhs = load_study(EXAMPLES / "lhs-10000.yaml")
    assert lhs.n_cases == 10_000 and lhs.simulation.integrator == "exact" and lhs.simulation.fidelity == "lti"
    assert lhs.design_spec.seed == 1 and lhs.simulation.duration == 5.0


def test_study_round_trips_through_json():
    s = load_study(EXAMPLES / "isolator-comparison.yaml")
    again = Study.model_validate(json.loads(json.dumps(s.model_dump(mode="json", by_alias=True))))
    assert again.design().names == s.design().names
    np.testing.assert_array_equal(
        again.design().values["stage_y_acceleration"], s.design().values["stage_y_acceleration"]
    )


def test_json_schema_describes_units():
    schema = Study.model_json_schema()
    assert {"name", "scene", "parameters", "design", "simulation"} <= set(schema["properties"])
    mass = schema["$defs"]["Stage"]["properties"]["mass"]
    assert {"type": "string"} in mass["anyOf"] and {"type": "number"} in mass["anyOf"]
    assert Scene.model_json_schema()["additionalProperties"] is False


def test_scene_dict_is_not_mutated_by_validation():
    d = base_scene()
    before = copy.deepcopy(d)
    Scene.model_validate(d)
    assert d == before


def test_a_check_naming_a_field_below_its_own_is_located_once():
    """A per-output tolerance check is raised at ``simulation.tolerance`` and names the output below it: the
    file check and the REST detail say where once, never ``simulation.tolerance.simulation.tolerance...``."""
    from isolab.studies.inputs.definitions import DefinitionError, check_definition

    scene = base_scene()
    scene["simulation"]["tolerance"] = {"peak_foo": "1 %"}
    (line,) = errors(scene)
    assert line.startswith("simulation.tolerance.peak_foo: unknown output 'peak_foo'"), line
    with pytest.raises(DefinitionError) as info:
        check_definition({"name": "t", "scene": scene, "design": {"type": "grid"}, "parameters": []})
    locs = [d["loc"] for d in info.value.details]
    assert ["body", "scene", "simulation", "tolerance", "peak_foo"] in locs, locs
