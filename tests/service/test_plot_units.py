"""Study figures in the units the study was written in, and units in the case table's CSV header.

One small grid study (Y acceleration 0.5 g .. 2 g x mount damping 2 % and 10 %, LTI with exact
discretisation over 1 s) runs in this process; its dataset goes through netCDF and the case table as the
service reads it, and the figure's matplotlib Axes are inspected (no PNG decoding).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from isolab.engine import simulate
from isolab.service.plots import studies as plots
from isolab.studies.inputs.study import Study, isolator_names
from isolab.studies.results.cases import CaseColumns, case_table, cases_csv, csv_header
from isolab.studies.results.dataset import to_dataset
from isolab.studies.units import readable_unit, shown_in, unit_value, written_unit

G = 9.80665
EXAMPLE = Path(__file__).resolve().parents[2] / "studies" / "examples" / "article-scriber.yaml"


def scriber(duration: str = "1 s") -> dict:
    scene = yaml.safe_load(EXAMPLE.read_text())
    scene["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": duration}
    return scene


SWEEP = {
    "name": "g-sweep",
    "scene": scriber(),
    "parameters": [
        {"path": "stages.y.profile.acceleration", "range": {"start": "0.5 g", "stop": "2 g", "num": 4}},
        {"path": "isolators.zeta", "values": ["2 %", "10 %"]},
    ],
    "design": {"type": "grid"},
}


@pytest.fixture(scope="module")
def table(tmp_path_factory: pytest.TempPathFactory) -> CaseColumns:
    """The sweep's case table, read back from its netCDF file as the service reads it."""
    study = Study.model_validate(SWEEP)
    sim = study.simulation
    result = simulate(
        study.batch(np.arange(study.n_cases)), fidelity=sim.fidelity, integrator=sim.integrator, dt=sim.dt
    )
    assert (result.status == 0).all()
    ds = to_dataset(
        result,
        study.design(),
        isolator_names=isolator_names(study.scene),
        point_names=list(study.scene.points),
    )
    path = tmp_path_factory.mktemp("plots") / "sweep.nc"
    ds.to_netcdf(path)
    with xr.open_dataset(path) as back:
        return case_table(back.load())


# ------------------------------------------------------------------------------------ units as written
def test_units_as_written_are_recorded_and_si_stays_the_cf_unit() -> None:
    assert written_unit("0.5 g", "acceleration") == "g"
    assert written_unit("5 %", "dimensionless") == "%"
    assert written_unit(" 20  kN / m ", "stiffness") == "kN / m"
    assert written_unit(0.5, "acceleration") is None  # a plain number is SI
    assert written_unit("1.2e6", "stiffness") is None
    assert written_unit("3 s", "length") is None  # not that dimension: nothing to show it in
    assert unit_value("g", "acceleration") == G and unit_value("%", "dimensionless") == 0.01
    assert unit_value("rad/s", "frequency") == pytest.approx(1 / (2 * np.pi))
    values, unit = shown_in([0.5 * G, 2 * G], "m/s^2", "g")
    assert unit == "g" and values.tolist() == pytest.approx([0.5, 2.0], rel=1e-15)
    assert shown_in([1.0], "m", "no-such-unit")[1] == "m"
    assert readable_unit("m", [0.0056, -0.001]) == ("mm", 1e-3)
    assert readable_unit("m", [4e-6]) == ("um", 1e-6)
    assert readable_unit("N", [2.5e4]) == ("kN", 1e3)
    assert readable_unit("rad", [3.9e-3]) == ("mrad", 1e-3)
    assert readable_unit("Hz", [3.5]) == ("Hz", 1.0) and readable_unit("1", [0.3]) == ("", 1.0)

    study = Study.model_validate(
        {
            "name": "units",
            "scene": scriber(),
            "parameters": [
                {
                    "path": "isolators.k.horizontal",
                    "range": {"start": "100 kN/m", "stop": "1e7", "scale": "log"},
                },
                {"path": "isolators.zeta", "range": {"start": "2 %", "stop": "40 %"}},
                {"path": "stages.y.mass", "range": {"start": 300, "stop": 1500}},
            ],
            "design": {"type": "lhs", "samples": 8},
        }
    )
    d = study.design()
    names = d.names
    assert [d.display_units[n] for n in names] == ["kN/m", "%", "kg"]
    assert [d.scales[n] for n in names] == ["log", "linear", "linear"]
    assert d.values[names[0]].min() >= 1e5 and d.values[names[0]].max() <= 1e7  # values stay SI
    listed = Study.model_validate(
        {
            "name": "listed",
            "scene": scriber(),
            "parameters": [{"path": "stages.y.profile.acceleration"}],
            "design": {
                "type": "list",
                "cases": [{"stage_y_acceleration": 9.8}, {"stage_y_acceleration": "2 g"}],
            },
        }
    ).design()
    assert listed.display_units == {"stage_y_acceleration": "g"}
    assert listed.values["stage_y_acceleration"].tolist() == [9.8, 2 * G]


def test_parameter_coordinates_carry_display_units_and_scale(table: CaseColumns) -> None:
    assert table.units["stage_y_acceleration"] == "m/s^2"  # CF units: SI
    assert table.display_units["stage_y_acceleration"] == "g"
    assert table.display_units["isolator_zeta"] == "%" and table.units["isolator_zeta"] == "1"
    assert table.scales["stage_y_acceleration"] == "linear"
    assert np.unique(table.data["stage_y_acceleration"]) == pytest.approx(np.array([0.5, 1, 1.5, 2]) * G)
    assert table.long_names["peak_displacement_y"] == "peak absolute displacement of the machine c.g., y"


# ----------------------------------------------------------------------------------------- figures
def test_a_sweep_written_in_g_is_drawn_in_g_with_outputs_in_mm(table: CaseColumns) -> None:
    fig = plots.study_figure(
        plots.series(table, "peak_displacement_y"),
        plots.series(table, "stage_y_acceleration"),
        title="g-sweep",
    )
    ax = fig.axes[0]
    assert ax.get_xlabel() == "stage_y_acceleration (g)"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["0.5", "1", "1.5", "2"]
    (line,) = ax.lines
    assert line.get_xdata().tolist() == pytest.approx([0.5, 1.0, 1.5, 2.0], rel=1e-12)
    lo, hi = ax.get_xlim()
    assert 0.4 <= lo <= 0.5 and 2.0 <= hi <= 2.1
    # the output in mm: the worst (largest) case over the damping at each acceleration, times 1000
    assert ax.get_ylabel().startswith("peak absolute displacement of the machine c.g., y (mm)")
    y, acc = table.data["peak_displacement_y"], table.data["stage_y_acceleration"]
    expected = [y[np.isclose(acc, a * G)].max() * 1e3 for a in (0.5, 1.0, 1.5, 2.0)]
    assert line.get_ydata().tolist() == pytest.approx(expected, rel=1e-12)
    assert 1.0 < expected[0] < 10.0  # millimetres of sway: the unit reads well at this size
    assert "(mm)" in ax.get_title() and "(g)" in ax.get_title()


def test_a_heat_map_in_g_and_percent_with_forces_in_kn(table: CaseColumns) -> None:
    fig = plots.study_figure(
        plots.series(table, "peak_isolator_force_z"),
        plots.series(table, "stage_y_acceleration"),
        x2=plots.series(table, "isolator_zeta"),
    )
    ax = fig.axes[0]
    assert ax.get_xlabel() == "stage_y_acceleration (g)" and ax.get_ylabel() == "isolator_zeta (%)"
    assert [t.get_text() for t in ax.get_yticklabels()] == ["2", "10"]
    mesh = ax.collections[0]
    force = table.data["peak_isolator_force_z"]
    assert float(mesh.get_array().max()) == pytest.approx(float(force.max()) / 1e3, rel=1e-12)
    assert fig.axes[1].get_ylabel().endswith("(kN)")  # the colour bar


def test_a_log_range_is_drawn_on_a_log_axis() -> None:
    k = np.geomspace(1e5, 1e7, 5)
    fig = plots.study_figure(
        plots.Series("settling_time", np.array([3.0, 2.0, 1.5, 1.2, 1.1]), "s"),
        plots.Series("isolator_kx", k, "N/m", display_unit="kN/m", scale="log"),
    )
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "linear"
    assert ax.get_xlabel() == "isolator_kx (kN/m)"
    assert ax.lines[0].get_xdata().tolist() == pytest.approx([100, 316.2278, 1000, 3162.278, 10000], rel=1e-6)
    # the same values without the log scale stay on a linear axis
    fig = plots.study_figure(plots.Series("t", np.ones(5), "s"), plots.Series("k", k, "N/m"))
    assert fig.axes[0].get_xscale() == "linear" and fig.axes[0].get_xlabel() == "k (N/m)"


def test_a_large_sampled_study_is_drawn_translucent() -> None:
    rng = np.random.default_rng(1)
    n = 10_000
    zeta = rng.uniform(0.02, 0.4, n)
    y = 1e-3 * (1.0 - zeta)
    fig = plots.study_figure(
        plots.Series("peak_displacement_y", y, "m"),
        plots.Series("isolator_zeta", zeta, "1", display_unit="%"),
        sampled=True,
    )
    ax = fig.axes[0]
    (points,) = ax.collections
    assert points.get_offsets().shape == (n, 2)
    assert points.get_alpha() == pytest.approx(plots.point_alpha(n)) and points.get_alpha() < 0.2
    assert float(points.get_offsets()[:, 0].max()) == pytest.approx(zeta.max() * 100)  # in percent
    assert ax.get_ylabel() == "peak_displacement_y (um)"  # 1 mm at most: micrometres read better
    assert plots.point_alpha(100) == 0.8 and plots.point_alpha(300) == 0.8  # few points: near opaque
    assert plots.point_alpha(1_000_000) == 0.05


def test_study_png_is_the_figure_drawn(table: CaseColumns) -> None:
    png = plots.study_png(plots.series(table, "settling_time"), plots.series(table, "isolator_zeta"))
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


# ------------------------------------------------------------------------------------------- CSV
def test_csv_header_carries_si_units_and_values_stay_si(table: CaseColumns) -> None:
    cols = ["case", "stage_y_acceleration", "isolator_zeta", "peak_displacement_y", "liftoff_any", "status"]
    text = cases_csv(table, cols, np.arange(table.n_cases))
    rows = list(csv.reader(io.StringIO(text)))
    assert rows[0] == [
        "case",
        "stage_y_acceleration [m/s^2]",
        "isolator_zeta",
        "peak_displacement_y [m]",
        "liftoff_any",
        "status",
    ]
    assert float(rows[1][1]) == pytest.approx(0.5 * G) and float(rows[1][2]) == pytest.approx(0.02)
    assert [float(r[3]) for r in rows[1:]] == table.data["peak_displacement_y"].tolist()
    assert csv_header("natural_frequency_1", "Hz") == "natural_frequency_1 [Hz]"
    assert csv_header("message", "") == "message"


def test_a_case_figure_and_its_title_in_readable_units() -> None:
    t = np.linspace(0.0, 1.0, 101)
    shift = np.zeros((101, 3))
    shift[:, 1] = 4e-3 * np.sin(2 * np.pi * 3.5 * t)  # 4 mm of sway
    turn = np.zeros((101, 3))
    turn[:, 0] = 2e-3 * np.sin(2 * np.pi * 6.2 * t)  # 2 mrad of pitch
    force = np.zeros((101, 2, 3))
    force[:, :, 2] = 1.2e4 * np.sin(2 * np.pi * 3.5 * t)[:, None]  # 12 kN on each mount
    fig = plots.case_figure(t, shift, turn, force, ["mount_0", "mount_1"])
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == [
        "c.g. translation (mm)",
        "rotation (mrad)",
        "isolator force X (kN)",
        "isolator force Y (kN)",
        "isolator force Z (kN)",
    ]
    assert fig.axes[0].lines[1].get_ydata().tolist() == pytest.approx((shift[:, 1] * 1e3).tolist(), rel=1e-12)
    assert fig.axes[4].lines[0].get_ydata().tolist() == pytest.approx(
        (force[:, 0, 2] / 1e3).tolist(), rel=1e-12
    )
    study = Study.model_validate(SWEEP)
    text = plots.parameters_text(study.case_values(7), study.design())
    assert text == "stage_y_acceleration=2 g, isolator_zeta=10 %"
