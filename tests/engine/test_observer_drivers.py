"""The two drivers of a linear level's stepped pair (``engine.integrators.stepping``): the output map's, for
the cases whose floor stands still and that are not recorded, and the general observer's, for the others.
Each case goes to one of them and gets, bit for bit, what it gets in a batch of its own; a run calls (and on
an empty kernel cache compiles) only the driver its cases need."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from isolab.engine import concat, general_observer_called, simulate
from isolab.engine.integrators import stepping
from tests.engine.scenes import scene, trapezoid_pieces

OUTPUTS = ("peak_displacement", "peak_rotation", "peak_isolator_force", "rms_displacement", "settling_time")


def still_and_moving() -> tuple:
    """A base whose stage moves 0.5 m, on a still floor and on a floor shaking 2 um at 7 Hz along x."""
    stage = {
        "mass": 800.0,
        "home": (0.0, 0.0, 0.3),
        "axis": (0.0, 1.0, 0.0),
        "pieces": trapezoid_pieces(0.5, 1.0, 10.0),
    }
    still = scene(stages=[stage], duration=1.0)
    moving = scene(stages=[stage], duration=1.0, floor_amp=(2e-6, 0.0, 0.0), floor_freq=(7.0, 1.0, 1.0))
    return still, moving


@pytest.mark.parametrize(("level", "integrator"), [("lti", "exact"), ("ltv", "rk4"), ("lti", "euler")])
def test_each_case_gets_from_its_observers_driver_what_it_gets_alone(level: str, integrator: str) -> None:
    still, moving = still_and_moving()
    # case 0: the output map; case 1: the general observer (the floor moves); case 2: the general one too
    # (recorded), beside a still case the map observes, the cases interleaved
    batch = concat([still, moving, still, still])
    many = simulate(batch, level, integrator, dt=2e-3, record=[2])
    alone = [
        simulate(still, level, integrator, dt=2e-3),
        simulate(moving, level, integrator, dt=2e-3),
        simulate(still, level, integrator, dt=2e-3, record=[0]),
    ]
    for c, one in zip((0, 1, 2, 3), (*alone, alone[0]), strict=True):
        for name in OUTPUTS:
            np.testing.assert_array_equal(
                getattr(many, name)[c], getattr(one, name)[0], err_msg=f"{name}[{c}]"
            )
    # the floor's shaking reaches the base: case 1 is not case 0 (the test could tell them apart)
    assert not np.array_equal(many.peak_displacement[1], many.peak_displacement[0])
    # the two observers agree to round-off where both can observe a case: the recorded still case
    np.testing.assert_allclose(many.peak_displacement[2], many.peak_displacement[0], rtol=1e-9, atol=1e-15)
    assert many.history["displacement"].shape[0] == 1  # the one recorded case


def test_the_general_observer_is_called_only_where_a_case_needs_it() -> None:
    still, moving = still_and_moving()
    assert not general_observer_called(still)
    assert general_observer_called(still, record=[0])
    assert general_observer_called(moving)
    assert general_observer_called(concat([still, moving]))
    drivers = stepping.ENTRIES["rk4", "ltv"]
    assert len(drivers) == 2 and len(stepping.ENTRIES["rk4", "nonlinear"]) == 1


CALLS = """
from isolab.engine import simulate
from isolab.engine.integrators import stepping
from tests.engine.test_observer_drivers import still_and_moving
still, moving = still_and_moving()
drivers = stepping.ENTRIES["rk4", "ltv"]
seen = []
for batch, record in ((still, None), (still, [0]), (moving, None)):
    simulate(batch, "ltv", "rk4", dt=2e-3, record=record)
    seen.append([len(d.signatures) for d in drivers])
print(seen)
"""


def test_a_run_loads_only_the_driver_its_cases_need() -> None:
    # a fresh process (the suite's kernel cache holds both drivers): a still, unrecorded case loads the
    # output map's driver alone, so on an empty cache it would compile that one alone
    out = subprocess.run(
        [sys.executable, "-c", CALLS], capture_output=True, text=True, timeout=110, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[-2] == "[[1, 0], [1, 1], [1, 1]]"
