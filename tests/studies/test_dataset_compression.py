"""Which variables a stored dataset compresses: those that shrink by half under zlib; every value reads
back the same whichever it is."""

from __future__ import annotations

from pathlib import Path

import netCDF4
import numpy as np
import xarray as xr

from isolab.studies.results.compression import (
    DEFLATE,
    PROBE_VALUES,
    deflate_encoding,
    probe_values,
    shrinks,
)
from isolab.studies.results.store import netcdf_encoding, write_netcdf


def cases_dataset(n: int = 20_000) -> xr.Dataset:
    rng = np.random.default_rng(3)
    peaks = rng.lognormal(-11.0, 1.0, (n, 3))  # peak displacements, m: little redundancy
    return xr.Dataset(
        {
            "peak_displacement": (("case", "axis"), peaks, {"units": "m", "long_name": "peak displacement"}),
            "point_settling_time": (("case",), np.full(n, np.nan), {"units": "s"}),  # a scene without points
            "status": (("case",), np.zeros(n, dtype=np.int8), {"long_name": "case status"}),
        },
        coords={"case": np.arange(n), "axis": ["x", "y", "z"]},
    )


def test_constant_and_missing_values_shrink_random_peaks_do_not() -> None:
    ds = cases_dataset()
    assert shrinks(ds.point_settling_time.values) and shrinks(ds.status.values)
    assert shrinks(np.zeros(5))
    assert not shrinks(ds.peak_displacement.values)
    assert not shrinks(np.array([], dtype=float))
    # a streamed variable (values not at hand) is always compressed
    assert deflate_encoding(None) == DEFLATE and deflate_encoding(ds.peak_displacement.values) == {}


def test_a_variable_is_judged_on_values_spread_over_it() -> None:
    # the probe takes runs of values from the start to the end: a variable whose first cases repeat (a
    # design sorted by a parameter, a first chunk of failed cases) but whose others do not is not compressed
    rng = np.random.default_rng(3)
    n = 100_000
    first_repeat = np.concatenate([np.zeros(PROBE_VALUES), rng.normal(size=n - PROBE_VALUES)])
    assert not shrinks(first_repeat)
    probe = probe_values(first_repeat)
    assert probe.size == PROBE_VALUES and probe[0] == 0.0 and probe[-1] == first_repeat[-1]
    assert shrinks(np.concatenate([np.full(n - 10, 0.25), rng.normal(size=10)]))
    small = rng.normal(size=PROBE_VALUES - 1)
    assert np.array_equal(probe_values(small), small)  # a small variable: all of it


def test_a_dataset_compresses_what_shrinks_and_reads_back_identical(tmp_path: Path) -> None:
    ds = cases_dataset()
    encoding = netcdf_encoding(ds)
    assert encoding["point_settling_time"]["zlib"] and "zlib" not in encoding["peak_displacement"]
    path = write_netcdf(ds, tmp_path / "study.nc")
    with netCDF4.Dataset(path) as raw:
        assert (
            raw["point_settling_time"].filters()["zlib"] and raw["point_settling_time"].filters()["shuffle"]
        )
        assert raw["status"].filters()["zlib"]
        assert not raw["peak_displacement"].filters()["zlib"]
    with xr.open_dataset(path) as back:
        xr.testing.assert_identical(back.load(), ds)
        assert back.peak_displacement.attrs["units"] == "m"
    # the 20,000 NaN and the statuses take next to nothing; the peaks their 480 kB
    plain = ds.peak_displacement.nbytes
    assert plain < path.stat().st_size < plain + 60_000
