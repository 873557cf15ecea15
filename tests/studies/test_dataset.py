"""Study results laid out as a labelled CF dataset, and chunked results put back in case order."""

from __future__ import annotations

import datetime as dt
import itertools
import json

import numpy as np
import pytest

from isolab.engine.results import DOF_NAMES, FAILED, OK, TIPPING, UNSTABLE, SimulationResult
from isolab.studies.questions.designs import Design
from isolab.studies.results.dataset import failed_arrays, from_chunks, result_arrays, to_dataset

FN = {"active": 1.0, "air": 3.0, "passive": 10.0}
ISOLATORS = ["front_left", "front_right", "rear_left", "rear_right"]
POINTS = ["tool", "camera"]


def fake_result(types: list[str], masses: np.ndarray, status: np.ndarray | None = None) -> SimulationResult:
    """Outputs that are closed-form functions of (isolator type, stage mass), to check where each lands."""
    c = len(types)
    fn = np.array([FN[t] for t in types])
    m = np.asarray(masses, dtype=float)
    base = m / fn**2 * 1e-6  # m: softer mounts and heavier stages move more
    status = np.full(c, OK, dtype=np.int8) if status is None else np.asarray(status, dtype=np.int8)
    n, p = len(ISOLATORS), len(POINTS)
    static = np.outer(m + 10_000.0, np.array([0.24, 0.26, 0.25, 0.25])) * 9.80665
    return SimulationResult(
        status=status,
        message=["" if s == OK else f"case went {s}" for s in status],
        dt=np.full(c, 2e-3),
        peak_displacement=base[:, None] * np.array([1.0, 2.0, 0.5]),
        peak_rotation=base[:, None] * np.array([3.0, 0.1, 0.01]),
        peak_point_displacement=base[:, None, None] * np.arange(1, p * 3 + 1).reshape(p, 3),
        peak_isolator_force=m[:, None, None] * np.arange(1, n * 3 + 1).reshape(n, 3),
        static_isolator_load=static,
        min_isolator_load=static - m[:, None] * fn[:, None] * 0.5,
        rms_displacement=base[:, None] * np.array([0.3, 0.6, 0.1]),
        final_displacement=base[:, None] * np.array([0.0, 0.1, -0.2, 1e3, 0.0, 0.0]),
        settling_time=1.0 / fn,
        settled=fn > 2.0,
        point_settling_time=np.outer(1.0 / fn, np.arange(1, p + 1)),
        peak_isolator_deflection=m[:, None, None] * np.arange(1, n * 3 + 1).reshape(n, 3) * 1e-9,
        max_isolator_load=static + m[:, None] * fn[:, None] * 0.5,
        natural_frequency=fn[:, None] * np.array([1.0, 1.1, 1.2, 1.5, 1.7, 2.0]),
        damping_ratio=np.full((c, 6), 0.05),
        mode_energy=np.tile(np.eye(6), (c, 1, 1)),
        mechanism=np.zeros((c, 6), dtype=bool) | (fn == 1.0)[:, None] & (np.arange(6) == 0),
        transmissibility=np.tile(fn[:, None] / 10.0, (1, 3)),
    )


def grid_design(order: np.ndarray | None = None) -> tuple[Design, list[str], np.ndarray]:
    types = ["active", "air", "passive"]
    masses = np.array([500.0, 1000.0])
    cases = list(itertools.product(types, masses))  # last varies fastest
    if order is not None:
        cases = [cases[i] for i in order]
    t = [c[0] for c in cases]
    m = np.array([c[1] for c in cases])
    design = Design(
        kind="grid",
        names=["isolator_type", "stage_y_mass"],
        values={"isolator_type": np.array(t), "stage_y_mass": m},
        levels={"isolator_type": np.array(types), "stage_y_mass": masses},
        paths={"isolator_type": "isolators.*.type", "stage_y_mass": "stages.y.mass"},
        units={"isolator_type": "", "stage_y_mass": "kg"},
    )
    return design, t, m


def test_grid_dimensions_and_selection_by_level() -> None:
    design, t, m = grid_design()
    ds = to_dataset(
        fake_result(t, m), design, isolator_names=ISOLATORS, point_names=POINTS, attrs={"title": "t"}
    )
    assert ds.peak_displacement.dims == ("isolator_type", "stage_y_mass", "axis")
    assert ds.sizes["isolator_type"] == 3 and ds.sizes["stage_y_mass"] == 2
    assert list(ds.isolator_type.values) == ["active", "air", "passive"]
    assert ds.isolator_type.dtype.kind == "U"
    sel = ds.sel(isolator_type="air", stage_y_mass=1000)
    expected = 1000.0 / 9.0 * 1e-6
    np.testing.assert_allclose(sel.peak_displacement.sel(axis="y"), 2 * expected, rtol=1e-15)
    np.testing.assert_allclose(sel.peak_rotation.sel(rotation="rx"), 3 * expected, rtol=1e-15)
    np.testing.assert_allclose(sel.peak_point_displacement.sel(point="camera", axis="x"), 4 * expected)
    np.testing.assert_allclose(sel.peak_isolator_force.sel(isolator="rear_left", axis="z"), 9 * 1000.0)
    np.testing.assert_allclose(sel.natural_frequency.sel(mode=6), 6.0)
    assert float(sel.mode_energy.sel(mode=2, dof="y")) == 1.0
    assert float(sel.settling_time) == pytest.approx(1 / 3)
    assert float(sel.settled) == 1.0
    # final displacement splits into translation (m) and rotation (rad)
    np.testing.assert_allclose(sel.final_displacement.values, [0.0, 0.1 * expected, -0.2 * expected])
    np.testing.assert_allclose(sel.final_rotation.sel(rotation="rx"), 1e3 * expected)
    # active mounts: first mode is a mechanism; passive: settled
    assert float(ds.mechanism.sel(isolator_type="active", stage_y_mass=500, mode=1)) == 1.0
    assert float(ds.mechanism.sel(isolator_type="air", stage_y_mass=500, mode=1)) == 0.0
    assert ds.mode.values.tolist() == [1, 2, 3, 4, 5, 6]
    assert ds.dof.values.tolist() == list(DOF_NAMES)
    assert ds.rotation.values.tolist() == ["rx", "ry", "rz"]


def test_grid_cells_follow_values_not_case_order() -> None:
    order = np.array([5, 0, 3, 1, 4, 2])
    design, t, m = grid_design(order)
    ds = to_dataset(fake_result(t, m), design, isolator_names=ISOLATORS, point_names=POINTS, attrs={})
    for typ, mass in itertools.product(FN, [500.0, 1000.0]):
        got = float(ds.peak_displacement.sel(isolator_type=typ, stage_y_mass=mass, axis="x"))
        assert got == pytest.approx(mass / FN[typ] ** 2 * 1e-6, rel=1e-15)


def test_liftoff_is_min_load_below_zero() -> None:
    design, t, m = grid_design()
    res = fake_result(t, m)
    res.min_isolator_load[3, 2] = -150.0
    ds = to_dataset(res, design, isolator_names=ISOLATORS, point_names=POINTS, attrs={})
    lifted = ds.liftoff.sel(isolator_type=t[3], stage_y_mass=m[3])
    assert lifted.values.tolist() == [0.0, 0.0, 1.0, 0.0]
    assert float(ds.liftoff.sum()) == 1.0


def test_cases_that_are_not_ok_are_missing_not_numbers() -> None:
    design, t, m = grid_design()
    status = np.array([OK, UNSTABLE, OK, TIPPING, OK, FAILED], dtype=np.int8)
    res = fake_result(t, m, status)  # the non-OK cases still carry (meaningless) numbers
    ds = to_dataset(res, design, isolator_names=ISOLATORS, point_names=POINTS, attrs={})
    bad = ds.sel(isolator_type="active", stage_y_mass=1000)  # case 1: unstable
    for name, var in bad.data_vars.items():
        if name in ("status", "message"):
            continue
        assert np.isnan(var.values).all(), name
    assert int(bad.status) == UNSTABLE
    assert bad.message.item() == f"case went {UNSTABLE}"
    good = ds.sel(isolator_type="active", stage_y_mass=500)
    assert int(good.status) == OK and good.message.item() == ""
    assert np.isfinite(good.peak_displacement.values).all()
    assert int(ds.status.sel(isolator_type="passive", stage_y_mass=1000)) == FAILED
    # three OK cases -> three finite settling times
    assert int(np.isfinite(ds.settling_time).sum()) == 3
    assert ds.status.dtype == np.int8
    assert ds.status.attrs["flag_values"].tolist() == [0, 1, 2, 3]
    assert ds.status.attrs["flag_meanings"] == "ok unstable tipping failed"


def test_every_variable_and_coordinate_has_units_and_long_name() -> None:
    design, t, m = grid_design()
    ds = to_dataset(fake_result(t, m), design, isolator_names=ISOLATORS, point_names=POINTS, attrs={})
    for name, var in ds.variables.items():
        assert var.attrs.get("units"), f"{name} has no units"
        assert var.attrs.get("long_name"), f"{name} has no long_name"
    assert ds.stage_y_mass.attrs["units"] == "kg"
    assert "stages.y.mass" in ds.stage_y_mass.attrs["long_name"]
    assert ds.peak_isolator_force.attrs["units"] == "N"
    assert ds.natural_frequency.attrs["units"] == "Hz"
    assert ds.settling_time.attrs["units"] == "s"


def test_settling_per_point_mount_deflection_and_largest_load_are_stored_and_tabled() -> None:
    from isolab.studies.results.cases import case_table

    design, t, m = grid_design()
    res = fake_result(t, m, np.array([OK, UNSTABLE, OK, OK, OK, OK], dtype=np.int8))
    ds = to_dataset(res, design, isolator_names=ISOLATORS, point_names=POINTS, attrs={})
    assert ds.point_settling_time.dims == ("isolator_type", "stage_y_mass", "point")
    assert ds.peak_isolator_deflection.dims == ("isolator_type", "stage_y_mass", "isolator", "axis")
    assert ds.max_isolator_load.dims == ("isolator_type", "stage_y_mass", "isolator")
    units = {"point_settling_time": "s", "peak_isolator_deflection": "m", "max_isolator_load": "N"}
    for name, unit in units.items():
        assert ds[name].attrs["units"] == unit and ds[name].attrs["long_name"]
    table = case_table(ds)
    # case 0: active, 500 kg; its columns are the worst isolator, or one point
    np.testing.assert_allclose(table.data["point_settling_time_camera"][0], 2.0 / FN["active"])
    np.testing.assert_allclose(table.data["peak_isolator_deflection_z"][0], 500.0 * 12 * 1e-9)
    np.testing.assert_allclose(table.data["max_isolator_load_max"][0], res.max_isolator_load[0].max())
    np.testing.assert_allclose(table.data["max_isolator_load_rear_left"][2], res.max_isolator_load[2, 2])
    np.testing.assert_allclose(table.data["peak_isolator_deflection_front_right_y"][2], 500.0 * 5 * 1e-9)
    for col in ("point_settling_time_tool", "peak_isolator_deflection_x", "max_isolator_load_max"):
        assert col in table.default and np.isnan(table.data[col][1])  # case 1 is unstable: missing
    assert "max_isolator_load_front_left" not in table.default
    assert "peak_isolator_deflection_front_left_z" not in table.default
    # a dataset stored before these outputs existed still tables
    old = case_table(ds.drop_vars(list(units)))
    assert "max_isolator_load_max" not in old.data and "point_settling_time_tool" not in old.data


def test_the_output_catalogue_describes_every_stored_output_and_its_columns() -> None:
    from isolab.engine.results import OUTPUTS
    from isolab.studies.answers.comparisons import criterion
    from isolab.studies.results.cases import NOT_TABULATED, case_table

    design, t, m = grid_design()
    ds = to_dataset(fake_result(t, m), design, isolator_names=ISOLATORS, point_names=POINTS, attrs={})
    stored = [str(v) for v in ds.data_vars if v not in ("status", "message")]
    assert stored == list(OUTPUTS)  # the catalogue's order, the step last
    for name, spec in OUTPUTS.items():
        assert ds[name].dims[2:] == spec.dims
        assert (ds[name].attrs["units"], ds[name].attrs["long_name"]) == (spec.unit, spec.long_name)
        assert (ds[name].encoding.get("dtype") == "int8") == spec.flag
    table = case_table(ds)
    tabled = set(table.outputs.values())
    assert tabled == set(OUTPUTS) - NOT_TABULATED
    for column, name in table.outputs.items():
        assert table.units[column] == OUTPUTS[name].unit
        assert table.kinds[column] == ("bool" if OUTPUTS[name].flag else "number")
    # a comparison judges each output's summary columns as the catalogue judges the output
    assert criterion(table, "min_isolator_load_min") == "highest"
    assert criterion(table, "liftoff_any") == "false"
    assert criterion(table, "peak_isolator_force_z") == "lowest"
    assert criterion(table, "settled") is None and criterion(table, "status") is None


def test_sampled_design_has_a_case_dimension_with_parameter_coordinates() -> None:
    rng = np.random.default_rng(3)
    masses = rng.uniform(200.0, 2000.0, 7)
    types = ["air", "active", "passive", "air", "air", "passive", "active"]
    design = Design(
        kind="sampled",
        names=["isolator_type", "stage_y_mass"],
        values={"isolator_type": np.array(types), "stage_y_mass": masses},
        levels={},
        paths={"isolator_type": "isolators.*.type", "stage_y_mass": "stages.y.mass"},
        units={"isolator_type": "", "stage_y_mass": "kg"},
    )
    ds = to_dataset(
        fake_result(types, masses),
        design,
        isolator_names=ISOLATORS,
        point_names=POINTS,
        attrs={"design": {"seed": 3, "method": "latin_hypercube"}},
    )
    assert ds.peak_displacement.dims == ("case", "axis")
    assert ds.case.values.tolist() == list(range(7))
    assert ds.stage_y_mass.dims == ("case",) and "stage_y_mass" not in ds.dims
    np.testing.assert_array_equal(ds.stage_y_mass.values, masses)
    air = ds.where(ds.isolator_type == "air", drop=True)
    np.testing.assert_allclose(air.peak_displacement.sel(axis="x"), masses[[0, 3, 4]] / 9.0 * 1e-6)
    summary = json.loads(ds.attrs["design"])
    assert summary["kind"] == "sampled" and summary["seed"] == 3 and summary["method"] == "latin_hypercube"
    assert summary["names"] == ["isolator_type", "stage_y_mass"]


def test_dataset_attributes_are_cf_and_pass_through() -> None:
    design, t, m = grid_design()
    definition = {"name": "iso", "design": {"kind": "grid"}}
    ds = to_dataset(
        fake_result(t, m),
        design,
        isolator_names=ISOLATORS,
        point_names=POINTS,
        attrs={
            "title": "isolator comparison",
            "study": definition,
            "engine_version": "0.1.0",
            "fidelity": "lti",
            "integrator": "exact",
            "dt": 2e-3,
            "added_later": [1, 2],
            "flag": True,
            "nothing": None,
        },
    )
    a = ds.attrs
    assert a["Conventions"] == "CF-1.10"
    assert a["title"] == "isolator comparison"
    assert json.loads(a["study"]) == definition
    assert a["engine_version"] == "0.1.0" and a["fidelity"] == "lti" and a["integrator"] == "exact"
    assert a["dt"] == 2e-3
    assert json.loads(a["added_later"]) == [1, 2] and a["flag"] == 1 and "nothing" not in a
    created = dt.datetime.fromisoformat(a["created"].replace("Z", "+00:00"))
    assert created.utcoffset() == dt.timedelta(0)
    assert abs((dt.datetime.now(dt.UTC) - created).total_seconds()) < 60
    assert a["created"] in a["history"]
    summary = json.loads(a["design"])
    assert summary["levels"] == {
        "isolator_type": ["active", "air", "passive"],
        "stage_y_mass": [500.0, 1000.0],
    }
    assert summary["paths"]["stage_y_mass"] == "stages.y.mass"


def test_layout_errors_name_the_problem() -> None:
    design, t, m = grid_design()
    with pytest.raises(ValueError, match="isolator_names"):
        to_dataset(fake_result(t, m), design, isolator_names=ISOLATORS[:3], point_names=POINTS, attrs={})
    with pytest.raises(ValueError, match="5 cases"):
        to_dataset(fake_result(t[:5], m[:5]), design, isolator_names=ISOLATORS, point_names=POINTS)
    # a grid with one cell given twice and one missing
    design.values["stage_y_mass"] = np.array([500.0, 500.0, 500.0, 1000.0, 500.0, 1000.0])
    with pytest.raises(ValueError, match="grid once each"):
        to_dataset(fake_result(t, m), design, isolator_names=ISOLATORS, point_names=POINTS)
    design.values["stage_y_mass"] = np.array([500.0, 750.0, 500.0, 1000.0, 500.0, 1000.0])
    with pytest.raises(ValueError, match="750"):
        to_dataset(fake_result(t, m), design, isolator_names=ISOLATORS, point_names=POINTS)


def test_chunks_reassemble_in_case_order() -> None:
    types = ["air", "active", "passive"] * 4
    masses = np.linspace(100.0, 1200.0, 12)
    status = np.full(12, OK, dtype=np.int8)
    status[4] = UNSTABLE
    full = fake_result(types, masses, status)
    chunks = [np.arange(0, 5), np.arange(5, 10), np.arange(10, 12)]
    parts = {}
    for k in (2, 0, 1):  # arrive out of order
        idx = chunks[k]
        sub = fake_result([types[i] for i in idx], masses[idx], full.status[idx])
        arrays = result_arrays(sub)
        arrays["indices"] = idx
        parts[k] = arrays
    got = from_chunks(parts, chunks, n_isolators=4, n_points=2)
    np.testing.assert_array_equal(got.status, full.status)
    assert got.message == full.message
    for name in ("peak_displacement", "peak_isolator_force", "mode_energy", "settled", "mechanism", "dt"):
        np.testing.assert_array_equal(getattr(got, name), getattr(full, name), err_msg=name)


def test_a_failed_chunk_becomes_failed_cases_with_its_message() -> None:
    types = ["air"] * 6
    masses = np.full(6, 800.0)
    chunks = [np.arange(0, 3), np.arange(3, 6)]
    parts = {0: result_arrays(fake_result(types[:3], masses[:3])), 1: failed_arrays(3, "worker died")}
    got = from_chunks(parts, chunks, n_isolators=4, n_points=2)
    assert got.status.tolist() == [OK, OK, OK, FAILED, FAILED, FAILED]
    assert got.message[3:] == ["worker died"] * 3
    assert np.isnan(got.peak_isolator_force[3:]).all() and got.peak_isolator_force[3:].shape == (3, 4, 3)
    assert np.isfinite(got.peak_isolator_force[:3]).all()


def test_from_chunks_rejects_gaps_and_mismatches() -> None:
    arrays = result_arrays(fake_result(["air"] * 3, np.full(3, 800.0)))
    with pytest.raises(ValueError, match=r"chunks \[1\]"):
        from_chunks({0: arrays}, [np.arange(3), np.arange(3, 6)], n_isolators=4, n_points=2)
    with pytest.raises(ValueError, match="exactly once"):
        from_chunks({0: arrays, 1: arrays}, [np.arange(3), np.arange(2, 5)], n_isolators=4, n_points=2)
    arrays["indices"] = np.array([3, 4, 5])
    with pytest.raises(ValueError, match="other cases"):
        from_chunks({0: arrays}, [np.arange(3)], n_isolators=4, n_points=2)
