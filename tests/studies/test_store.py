"""The study store: atomic netCDF files, the SQLite catalog, per-chunk persistence, id checks."""

from __future__ import annotations

import datetime as dt
import json
import os
import sqlite3
import threading
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr

from isolab.engine.results import OK, UNSTABLE, SimulationResult
from isolab.studies.questions.designs import Design
from isolab.studies.results.dataset import to_dataset
from isolab.studies.results.store import Store, StudyFilter, StudyNotFound, check_id, write_netcdf

ISOLATORS = ["a", "b", "c", "d"]
POINTS = ["tool"]
FN = {"active": 1.0, "air": 3.0, "passive": 10.0}


def study_dataset(unstable_case: int | None = None, scale: float = 1.0) -> xr.Dataset:
    """A 3 x 2 grid (isolator_type x stage_y_mass) whose outputs are closed-form in the parameters."""
    types = np.array(["active", "active", "air", "air", "passive", "passive"])
    masses = np.array([500.0, 1000.0] * 3)
    fn = np.array([FN[t] for t in types])
    c = len(types)
    status = np.full(c, OK, dtype=np.int8)
    if unstable_case is not None:
        status[unstable_case] = UNSTABLE
    base = scale * masses / fn**2 * 1e-6
    res = SimulationResult(
        status=status,
        message=["" if s == OK else "step too large for the stiffest mode" for s in status],
        dt=np.full(c, 2e-3),
        peak_displacement=base[:, None] * np.array([1.0, 2.0, 0.5]),
        peak_rotation=base[:, None] * np.array([3.0, 0.1, 0.01]),
        peak_point_displacement=base[:, None, None] * np.array([[1.0, 2.0, 3.0]]),
        peak_isolator_force=masses[:, None, None] * np.ones((4, 3)),
        static_isolator_load=np.full((c, 4), 25_000.0),
        min_isolator_load=np.full((c, 4), 25_000.0) - masses[:, None] * 30.0,
        rms_displacement=base[:, None] * np.array([0.3, 0.6, 0.1]),
        final_displacement=np.zeros((c, 6)),
        settling_time=1.0 / fn,
        settled=fn > 2.0,
        point_settling_time=(1.0 / fn)[:, None],
        peak_isolator_deflection=masses[:, None, None] * np.full((4, 3), 1e-8),
        max_isolator_load=np.full((c, 4), 25_000.0) + masses[:, None] * 30.0,
        natural_frequency=fn[:, None] * np.linspace(1.0, 2.0, 6),
        damping_ratio=np.full((c, 6), 0.05),
        mode_energy=np.tile(np.eye(6), (c, 1, 1)),
        mechanism=np.zeros((c, 6), dtype=bool),
        transmissibility=np.zeros((c, 3)),
    )
    design = Design(
        kind="grid",
        names=["isolator_type", "stage_y_mass"],
        values={"isolator_type": types, "stage_y_mass": masses},
        levels={
            "isolator_type": np.array(["active", "air", "passive"]),
            "stage_y_mass": np.array([500.0, 1000.0]),
        },
        paths={"isolator_type": "isolators.*.type", "stage_y_mass": "stages.y.mass"},
        units={"isolator_type": "", "stage_y_mass": "kg"},
    )
    return to_dataset(
        res,
        design,
        isolator_names=ISOLATORS,
        point_names=POINTS,
        attrs={
            "title": "isolator comparison",
            "study": {"name": "iso", "n": 6},
            "engine_version": "0.1.0",
            "fidelity": "lti",
            "integrator": "exact",
            "dt": 2e-3,
        },
    )


@pytest.fixture
def store(tmp_path: Path) -> Store:
    return Store(tmp_path / "store")


def new_id(store: Store, name: str = "iso", **kw) -> str:
    return store.create({"name": name}, name=name, n_cases=6, parameters=["isolator_type"], **kw)


# ------------------------------------------------------------------------------------------ netCDF
def test_dataset_round_trips_through_netcdf(store: Store) -> None:
    ds = study_dataset(unstable_case=3)
    sid = new_id(store)
    path = store.write_dataset(sid, ds)
    assert path == store.root / "studies" / f"{sid}.nc"
    with xr.open_dataset(path) as raw:  # plain xarray, as any user would
        back = raw.load()
    assert list(back.isolator_type.values) == ["active", "air", "passive"]
    assert back.stage_y_mass.values.tolist() == [500.0, 1000.0]
    assert back.peak_displacement.dims == ("isolator_type", "stage_y_mass", "axis")
    xr.testing.assert_allclose(back.peak_displacement, ds.peak_displacement, rtol=0, atol=0)
    np.testing.assert_array_equal(back.settling_time.values, ds.settling_time.values)
    # the selection users make works on the file
    sel = back.sel(isolator_type="air", stage_y_mass=500)
    assert float(sel.peak_displacement.sel(axis="y")) == pytest.approx(2 * 500 / 9 * 1e-6, rel=1e-15)
    assert float(sel.settled) == 1.0
    # the unstable case (air, 1000 kg) is missing, not a number; its status and message survive
    bad = back.sel(isolator_type="air", stage_y_mass=1000)
    for name in (
        "peak_displacement",
        "peak_isolator_force",
        "natural_frequency",
        "settling_time",
        "dt",
        "settled",
        "liftoff",
        "mechanism",
    ):
        assert np.isnan(bad[name].values).all(), name
    assert int(bad.status) == UNSTABLE and back.status.dtype == np.int8
    assert bad.message.item() == "step too large for the stiffest mode"
    assert back.sel(isolator_type="air", stage_y_mass=500).message.item() == ""
    assert back.status.attrs["flag_meanings"] == "ok unstable tipping failed"
    assert back.status.attrs["flag_values"].tolist() == [0, 1, 2, 3]
    # yes/no outputs keep their values
    np.testing.assert_array_equal(back.liftoff.values, ds.liftoff.values)
    assert float(back.liftoff.sel(isolator_type="passive", stage_y_mass=1000).sum()) == 4.0
    # every variable and coordinate still has CF units and long_name
    for name, var in back.variables.items():
        assert var.attrs.get("units") and var.attrs.get("long_name"), name
        assert var.attrs["units"] == ds[name].attrs["units"]
    assert back.attrs == ds.attrs
    assert json.loads(back.attrs["study"]) == {"name": "iso", "n": 6}
    assert back.attrs["Conventions"] == "CF-1.10"


def test_missing_values_are_written_with_fill_values(store: Store) -> None:
    sid = new_id(store)
    store.write_dataset(sid, study_dataset(unstable_case=0))
    with netCDF4.Dataset(store.path(sid)) as nc:
        pd = nc.variables["peak_displacement"]
        assert np.isnan(pd._FillValue)
        pd.set_auto_mask(False)
        raw = pd[:]
        assert np.isnan(raw[0, 0]).all() and np.isfinite(raw[0, 1]).all()
        settled = nc.variables["settled"]
        assert settled.dtype == np.int8 and settled._FillValue == -1
        settled.set_auto_mask(False)
        assert settled[:].tolist() == [[-1, 0], [1, 1], [1, 1]]  # active (1 Hz) does not settle


def test_open_dataset_does_not_hold_the_file(store: Store) -> None:
    sid = new_id(store)
    store.write_dataset(sid, study_dataset())
    ds = store.open_dataset(sid)
    os.replace(store.path(sid), store.root / "moved.nc")  # works on a closed file, data still in memory
    force = ds.peak_isolator_force.sel(isolator_type="air", stage_y_mass=1000, isolator="c", axis="x")
    assert float(force) == 1000.0
    with pytest.raises(StudyNotFound):
        store.open_dataset(sid)


def test_a_write_that_fails_half_way_leaves_the_previous_file(store: Store, monkeypatch) -> None:
    sid = new_id(store)
    store.write_dataset(sid, study_dataset(scale=1.0))
    before = store.path(sid).read_bytes()

    def broken_to_netcdf(self, path, *args, **kwargs):
        with open(path, "wb") as f:
            f.write(b"\x89HDF\r\n\x1a\n" + b"\0" * 512)  # a truncated file
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", broken_to_netcdf)
    with pytest.raises(OSError, match="disk full"):
        store.write_dataset(sid, study_dataset(scale=2.0))
    monkeypatch.undo()
    assert store.path(sid).read_bytes() == before
    assert sorted(p.name for p in store.studies_dir.iterdir()) == [f"{sid}.nc"]
    assert store.dataset_ids() == [sid]
    back = store.open_dataset(sid)
    assert float(back.peak_displacement.sel(isolator_type="active", stage_y_mass=500, axis="x")) == 500e-6
    # and a successful rewrite replaces it
    store.write_dataset(sid, study_dataset(scale=2.0))
    assert (
        float(
            store.open_dataset(sid).peak_displacement.sel(isolator_type="active", stage_y_mass=500, axis="x")
        )
        == 1000e-6
    )


def test_write_netcdf_to_any_path_is_atomic(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "result.nc"
    write_netcdf(study_dataset(), out)
    before = out.read_bytes()
    monkeypatch.setattr(xr.Dataset, "to_netcdf", lambda self, path, **kw: (_ for _ in ()).throw(OSError("x")))
    with pytest.raises(OSError):
        write_netcdf(study_dataset(scale=3.0), out)
    assert out.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["result.nc"]


# ----------------------------------------------------------------------------------------- catalog
def test_catalog_row_and_updates(store: Store) -> None:
    definition = {"name": "iso", "design": {"kind": "grid"}}
    sid = store.create(
        definition,
        name="iso",
        n_cases=6,
        parameters=["isolator_type", "stage_y_mass"],
        isolator_types=["active", "air"],
        fidelity="lti",
        integrator="exact",
    )
    assert check_id(sid) == sid
    row = store.get(sid)
    assert row["status"] == "queued" and row["n_cases"] == 6 and row["n_done"] == 0 and row["n_failed"] == 0
    assert row["parameters"] == ["isolator_type", "stage_y_mass"]
    assert row["isolator_types"] == ["active", "air"]
    assert row["definition"] == definition and row["fidelity"] == "lti" and row["integrator"] == "exact"
    assert row["started"] is None and row["finished"] is None and row["error"] is None
    created = dt.datetime.fromisoformat(row["created"])
    assert abs((dt.datetime.now(dt.UTC) - created).total_seconds()) < 60
    store.update(sid, status="running", started=dt.datetime(2030, 1, 2, 3, 4, 5), n_done=4, n_failed=1)
    row = store.get(sid)
    assert (row["status"], row["n_done"], row["n_failed"]) == ("running", 4, 1)
    assert row["started"] == "2030-01-02T03:04:05.000000+00:00"
    with pytest.raises(ValueError, match="status"):
        store.update(sid, status="exploded")
    with pytest.raises(ValueError, match="created"):
        store.update(sid, created="2020-01-01")
    with pytest.raises(StudyNotFound):
        store.update("0" * 32, status="done")
    with pytest.raises(StudyNotFound):
        store.get("0" * 32)
    with sqlite3.connect(store.catalog_path) as con:
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_catalog_list_filters_in_sql(store: Store) -> None:
    t0 = dt.datetime(2030, 5, 1, tzinfo=dt.UTC)
    ids = {}
    specs = [
        ("alpha", "done", ["air"], 0),
        ("alpha", "failed", ["active", "air"], 1),
        ("beta", "done", ["passive"], 2),
        ("beta", "running", ["active"], 3),
        ("gamma", "queued", [], 4),
    ]
    for name, status, types, day in specs:
        ids[(name, day)] = store.create(
            {"name": name},
            name=name,
            n_cases=1,
            isolator_types=types,
            status=status,
            created=t0 + dt.timedelta(days=day),
        )

    def names(rows):
        return [(r["name"], r["status"]) for r in rows]

    assert names(store.list()) == [
        ("gamma", "queued"),
        ("beta", "running"),
        ("beta", "done"),
        ("alpha", "failed"),
        ("alpha", "done"),
    ]  # newest first
    assert names(store.list(StudyFilter(name="alpha"))) == [("alpha", "failed"), ("alpha", "done")]
    assert names(store.list(StudyFilter(status="done"))) == [("beta", "done"), ("alpha", "done")]
    assert names(store.list(StudyFilter(isolator_type="active"))) == [
        ("beta", "running"),
        ("alpha", "failed"),
    ]
    assert names(store.list(StudyFilter(isolator_type="air", status="done"))) == [("alpha", "done")]
    assert names(store.list(StudyFilter(created_after=t0 + dt.timedelta(days=2)))) == [
        ("gamma", "queued"),
        ("beta", "running"),
        ("beta", "done"),
    ]
    assert names(
        store.list(StudyFilter(created_after="2030-05-02T00:00:00Z", created_before="2030-05-03T12:00:00"))
    ) == [
        ("beta", "done"),
        ("alpha", "failed"),
    ]
    assert names(store.list(limit=2)) == [("gamma", "queued"), ("beta", "running")]
    assert names(store.list(limit=2, offset=2)) == [("beta", "done"), ("alpha", "failed")]
    assert names(store.list(limit=2, offset=4)) == [("alpha", "done")]
    assert (
        store.count() == 5
        and store.count(StudyFilter(isolator_type="air")) == 2
        and store.count(StudyFilter(name="nope")) == 0
    )
    with pytest.raises(ValueError, match="status"):
        store.list(StudyFilter(status="nope"))
    with pytest.raises(ValueError, match="created_after"):
        store.list(StudyFilter(created_after="yesterday"))
    with pytest.raises(ValueError, match="limit"):
        store.list(limit=0)


def test_listing_never_opens_netcdf(store: Store, monkeypatch) -> None:
    sid = new_id(store, isolator_types=["air"])
    store.write_dataset(sid, study_dataset())

    def forbidden(*a, **k):
        raise AssertionError("listing opened a netCDF file")

    monkeypatch.setattr(xr, "open_dataset", forbidden)
    monkeypatch.setattr(netCDF4, "Dataset", forbidden)
    assert [r["id"] for r in store.list(StudyFilter(isolator_type="air"))] == [sid]


def test_delete_removes_row_file_and_chunks(store: Store) -> None:
    keep, gone = new_id(store, "keep"), new_id(store, "gone")
    for sid in (keep, gone):
        store.write_dataset(sid, study_dataset())
        store.save_chunk(sid, 0, {"status": np.zeros(3, np.int8)})
    assert store.delete(gone) is True
    with pytest.raises(StudyNotFound):
        store.get(gone)
    assert not store.path(gone).exists() and not store.chunk_dir(gone).exists()
    assert store.delete(gone) is False
    assert [r["id"] for r in store.list()] == [keep]
    assert store.path(keep).exists() and store.done_chunks(keep) == {0}


def test_concurrent_writers_from_threads(store: Store) -> None:
    sid = new_id(store)
    errors: list[BaseException] = []

    def work(i: int) -> None:
        try:
            for j in range(10):
                store.create({"i": i}, name=f"t{i}", n_cases=j)
                store.update(sid, n_done=i * 10 + j)
        except BaseException as err:  # pragma: no cover - reported below
            errors.append(err)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert store.count() == 61 and store.count(StudyFilter(name="t3")) == 10


# ----------------------------------------------------------------------------------------- ids
@pytest.mark.parametrize(
    "bad",
    [
        "../etc",
        "../../etc/passwd",
        "A" * 32,
        "ABCDEF0123456789abcdef0123456789",
        "a" * 31,
        "a" * 33,
        "g" * 32,
        "/" + "a" * 31,
        "a" * 31 + "/",
        "",
        "a" * 16 + "\0" + "a" * 15,
        123,
    ],
)
def test_bad_ids_never_reach_a_path(store: Store, bad) -> None:
    for call in (
        store.path,
        store.get,
        store.delete,
        store.open_dataset,
        store.chunk_dir,
        store.done_chunks,
        store.load_chunks,
        lambda i: store.update(i, n_done=1),
        lambda i: store.save_chunk(i, 0, {"x": np.zeros(1)}),
    ):
        with pytest.raises(ValueError, match="study_id"):
            call(bad)
    assert all(
        p.name in ("studies", ".reserve") or p.name.startswith("catalog.sqlite") for p in store.root.iterdir()
    )
    assert list(store.studies_dir.iterdir()) == []


# --------------------------------------------------------------------------------------- chunks
def test_a_done_studys_leftover_chunks_are_swept_and_no_others(store: Store) -> None:
    # a run removes a study's chunks right after marking it done: a stop in between leaves them for the sweep
    done, running, failed = new_id(store, "done"), new_id(store, "running"), new_id(store, "failed")
    for sid, status in ((done, "done"), (running, "running"), (failed, "failed")):
        store.save_chunk(sid, 0, {"status": np.zeros(3, np.int8)})
        store.update(sid, status=status)
    stranger = store.studies_dir / ("a" * 32 + ".chunks")  # not in the catalog: not the store's to remove
    stranger.mkdir()
    assert store.sweep_chunks() == [done]
    assert not store.chunk_dir(done).exists() and stranger.is_dir()
    assert store.done_chunks(running) == {0} and store.done_chunks(failed) == {0}  # they resume from these
    assert store.sweep_chunks() == []


def test_chunks_persist_and_reload(store: Store) -> None:
    sid = new_id(store)
    assert store.done_chunks(sid) == set() and store.load_chunks(sid) == {}
    a0 = {
        "status": np.array([0, 1], np.int8),
        "message": np.array(["", "unstable at dt 2 ms"]),
        "peak_displacement": np.array([[1e-6, 2e-6, 3e-6], [np.nan] * 3]),
        "indices": np.array([0, 1]),
    }
    a2 = {
        "status": np.array([3], np.int8),
        "message": np.array(["chunk 2 failed: KilledWorker"]),
        "indices": np.array([4]),
    }
    store.save_chunk(sid, 0, a0)
    store.save_chunk(sid, 2, a2)
    assert store.done_chunks(sid) == {0, 2}
    got = store.load_chunks(sid)
    assert set(got) == {0, 2}
    np.testing.assert_array_equal(got[0]["peak_displacement"], a0["peak_displacement"])
    assert got[0]["message"].tolist() == ["", "unstable at dt 2 ms"]
    assert got[2]["message"].tolist() == ["chunk 2 failed: KilledWorker"]
    assert got[0]["status"].dtype == np.int8
    assert sorted(p.name for p in store.chunk_dir(sid).iterdir()) == ["0.npz", "2.npz"]
    with pytest.raises(ValueError, match="object"):
        store.save_chunk(sid, 1, {"message": np.array(["a", None], dtype=object)})
    with pytest.raises(ValueError, match="chunk_index"):
        store.save_chunk(sid, -1, a2)
    assert store.done_chunks(sid) == {0, 2}
    plan = [np.arange(0, 2), np.arange(2, 4), np.arange(4, 5)]
    assert store.load_chunk_plan(sid) is None
    store.save_chunk_plan(sid, plan)
    assert [p.tolist() for p in store.load_chunk_plan(sid)] == [[0, 1], [2, 3], [4]]
    assert store.done_chunks(sid) == {0, 2}  # the plan is not a chunk
    store.clear_chunks(sid)
    assert store.done_chunks(sid) == set() and not store.chunk_dir(sid).exists()


def test_a_catalog_from_before_the_step_column_is_migrated(tmp_path: Path) -> None:
    # a catalog written before `dt` was recorded: opening it adds the column, old rows read None
    from isolab.studies.results import catalog as catalog_module

    old_schema = catalog_module._SCHEMA.replace("    dt REAL,\n", "")
    assert "dt REAL" not in old_schema
    with sqlite3.connect(tmp_path / "catalog.sqlite") as con:
        con.executescript(old_schema)
        con.execute(
            "INSERT INTO studies (id, name, status, created, n_cases, definition) VALUES "
            "(?, 'old', 'done', '2026-01-01T00:00:00.000000+00:00', 3, '{}')",
            ("a" * 32,),
        )
    s = Store(tmp_path)
    assert s.get("a" * 32)["dt"] is None
    sid = s.create({}, name="new", n_cases=1, fidelity="lti", integrator="exact", dt=0.002)
    s.update("a" * 32, dt=0.001)
    assert s.get(sid)["dt"] == 0.002 and s.get("a" * 32)["dt"] == 0.001


def test_a_study_registers_as_a_typed_record_that_reads_as_its_row(store: Store) -> None:
    from isolab.studies.inputs.study import load_study
    from isolab.studies.results.records import COLUMNS, StudyRecord

    study = load_study(Path(__file__).parents[2] / "studies" / "examples" / "isolator-comparison.yaml")
    sid = store.register(study)
    record = store.get(sid)
    assert isinstance(record, StudyRecord) and record.id == sid and record.status == "queued"
    assert record.name == "isolator-comparison" and record.n_cases == 12 and record.n_done == 0
    assert record.parameters == ["isolator_type", "stage_y_acceleration"]
    assert record.isolator_types == ["active", "air", "elastomer"]
    assert (record.fidelity, record.integrator, record.dt) == ("ltv", "rk4", 0.001)
    assert record.definition["name"] == "isolator-comparison" and record.generation is None
    # the record reads as the catalog row it is
    assert record["n_cases"] == 12 and record.get("generations") is None and list(record) == list(COLUMNS)
    assert dict(record)["isolator_types"] == ["active", "air", "elastomer"]
    with pytest.raises(KeyError):
        record["nope"]
    listed = store.list(StudyFilter(isolator_type="elastomer", status="queued"))
    assert listed == [record] and store.count(StudyFilter(isolator_type="air")) == 1
