"""Studies whose cases cannot succeed (issue 13, item 5).

A scene that is a mechanism or tips over in every case (zero stiffness on every mount) is a 422 naming
``isolators``, found by the modal analysis of the cases that span the study, without integrating; a study
whose every case fails ends ``failed`` with the reason; one with some failed cases says how many.
"""

from __future__ import annotations

import time
from typing import Any

import httpx
import pytest

from benchmarks.live_service import quick_scene, thread_server, wait_finished
from isolab.service.api.app import create_app
from isolab.service.settings import Settings
from isolab.studies.inputs.definitions import DefinitionError, check_definition
from tests.shared_cluster import shared_scheduler


def study(
    name: str, scene: dict | None = None, presets: list[str] | None = None, **isolators: Any
) -> dict[str, Any]:
    scene = scene or quick_scene()
    scene["isolators"].update(isolators)
    return {
        "name": name,
        "scene": scene,
        "parameters": [
            {"path": "isolators.preset", "values": presets or ["air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "values": ["1 g", "2 g"]},
        ],
    }


@pytest.mark.parametrize(
    ("stiffness", "why"),
    [({"x": 0, "y": 0, "z": 0}, "tips over"), ({"horizontal": 0}, "is a mechanism")],
    ids=["zero-everywhere", "zero-horizontal"],
)
def test_a_study_that_is_a_mechanism_in_every_case_is_refused_naming_isolators(
    stiffness: dict, why: str
) -> None:
    start = time.perf_counter()
    with pytest.raises(DefinitionError) as err:
        check_definition(study("mechanism", k=stiffness), 1000)
    assert time.perf_counter() - start < 1.0
    (d,) = err.value.details
    assert d["loc"] == ["body", "scene", "isolators"]
    assert why in d["msg"] and "every case would fail" in d["msg"]


def test_a_stiffness_range_that_reaches_zero_at_one_corner_only_is_accepted() -> None:
    body = study("half-mechanism")
    body["parameters"].append({"path": "isolators.k.x", "values": [0, "1e6 N/m"]})
    assert check_definition(body, 1000).n_cases == 8


def unstable_scene() -> dict:
    """Euler at 25 ms without sub-steps: unstable on elastomer mounts (fastest mode ~18 Hz), stable on air
    mounts (~5 Hz)."""
    scene = quick_scene(fidelity="ltv", integrator="euler", dt="25 ms")
    scene["simulation"]["auto_step"] = False
    return scene


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory):
    settings = Settings(
        data_dir=tmp_path_factory.mktemp("data"), scheduler_address=shared_scheduler(1), max_cases=1000
    )
    with thread_server(create_app(settings)) as url, httpx.Client(base_url=url, timeout=60.0) as client:
        yield client


def run(http: httpx.Client, body: dict, timeout: float = 120.0) -> dict:
    r = http.post("/studies", json=body)
    assert r.status_code == 202, r.text
    return wait_finished(http, r.json()["id"], timeout)


@pytest.mark.slow
def test_over_http_a_mechanism_is_a_422_naming_isolators(http: httpx.Client) -> None:
    r = http.post("/studies", json=study("mechanism", k={"x": 0, "y": 0, "z": 0}))
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["body", "scene", "isolators"]


@pytest.mark.slow
def test_a_study_whose_every_case_fails_ends_failed_saying_why(http: httpx.Client) -> None:
    info = run(http, study("all-unstable", scene=unstable_scene(), presets=["elastomer"]))
    assert info["status"] == "failed", info
    assert info["progress"]["failed"] == 2
    assert info["error"].startswith("every case failed (2 unstable; case 0: dt = 0.025 s is past"), info[
        "error"
    ]
    assert info["failures"].startswith("2 of 2 cases failed")


@pytest.mark.slow
def test_a_study_with_some_failed_cases_is_done_and_says_how_many(http: httpx.Client) -> None:
    info = run(http, study("half-unstable", scene=unstable_scene(), presets=["air", "elastomer"]))
    assert info["status"] == "done", info
    assert info["progress"] == {"done": 4, "total": 4, "failed": 2}
    assert info["error"] is None
    assert info["failures"].startswith("2 of 4 cases failed (status not ok)")
    cases = http.get(f"/studies/{info['id']}/cases", params={"format": "json"}).json()
    assert cases, cases
