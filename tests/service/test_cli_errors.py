"""What ``isolab run`` and ``isolab simulate`` tell a user whose file is wrong, the compile notice of a
first run, and the mode of the files ``isolab run`` and ``isolab fetch`` write.

A wrong file gives one ``error: field: reason`` line per problem on stderr and exit code 2: no traceback, no
progress bar, no pydantic link, a stage by its name and the keys as the file writes them. ``isolab run``
holds a study to the case limit a submitted one has (ISOLAB_MAX_CASES).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import httpx
import pytest
import yaml
from typer.testing import CliRunner

from isolab.service.cli import app as cli_app
from isolab.service.cli import local as local_commands
from isolab.service.client import Client, read_study_file
from isolab.studies.inputs.definitions import DefinitionError, check_definition
from isolab.studies.inputs.file_checks import in_user_words
from isolab.studies.results.store import copy_atomic, new_file_mode
from isolab.studies.run.kernel_cache import entry_kernels, kernels_cached

BAR = "━"  # what rich draws a progress bar with


EXAMPLE = Path(__file__).resolve().parents[2] / "studies" / "examples" / "article-scriber.yaml"


def scene() -> dict:
    """The article's scriber (stages y and x), short and on the exact integrator: fast to run."""
    s = yaml.safe_load(EXAMPLE.read_text())
    s["simulation"] = {"fidelity": "lti", "integrator": "exact", "dt": "2 ms", "duration": "4 s"}
    return s


def write(path: Path, data: dict) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def study(tmp_path: Path, **keys) -> Path:
    """A study file naming ``scene.yaml`` beside it, two isolator types unless ``keys`` say otherwise."""
    write(tmp_path / "scene.yaml", scene())
    data = {
        "name": "errors",
        "scene_file": "scene.yaml",
        "parameters": [{"path": "isolators.preset", "values": ["air", "elastomer"]}],
    }
    return write(tmp_path / "study.yaml", data | keys)


def invoke(*args: str, env: dict | None = None):
    return CliRunner().invoke(cli_app, list(args), env=env)


def assert_one_line_error(result, *expected: str) -> str:
    """Exit code 2, nothing but one ``error:`` line on stderr holding every expected text, no stdout."""
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert result.stdout == ""  # no progress bar, no partial output
    for text in ("Traceback", BAR, "errors.pydantic.dev", "validation error for", "[type="):
        assert text not in result.output
    for text in expected:
        assert text in lines[0], lines[0]
    return lines[0]


# ------------------------------------------------------------------------------------------ isolab run
def test_run_a_missing_scene_file_is_one_line(tmp_path: Path) -> None:
    path = study(tmp_path, scene_file="nowhere.yaml")
    r = invoke("run", str(path), "-o", str(tmp_path / "out.nc"))
    assert_one_line_error(r, "scene_file: no file", "nowhere.yaml")
    assert not (tmp_path / "out.nc").exists()


def test_run_a_missing_study_file_is_one_line(tmp_path: Path) -> None:
    r = invoke("run", str(tmp_path / "absent.yaml"), "-o", str(tmp_path / "out.nc"))
    assert_one_line_error(r, "absent.yaml: no such file")


def test_run_a_value_that_breaks_the_scene_names_the_stage(tmp_path: Path) -> None:
    path = study(tmp_path, parameters=[{"path": "stages.y.mass", "values": ["-5 kg", "100 kg"]}])
    line = assert_one_line_error(invoke("run", str(path), "-o", str(tmp_path / "out.nc")))
    assert "-5 kg" in line and "stages.y.mass" in line and "stages.0" not in line and "stages[0]" not in line


def test_run_a_wrong_stage_names_it_not_its_index(tmp_path: Path) -> None:
    s = scene()
    s["stages"][1]["parent"] = "nowhere"  # the x stage rides on no stage
    write(tmp_path / "scene.yaml", s)
    path = write(tmp_path / "study.yaml", {"name": "s", "scene_file": "scene.yaml"})
    line = assert_one_line_error(invoke("run", str(path), "-o", str(tmp_path / "out.nc")))
    assert line == "error: scene.stages.x.parent: no stage named 'nowhere' (stages: y, x)"


def test_run_speaks_the_keys_of_the_file(tmp_path: Path) -> None:
    s = scene()
    del s["isolators"]["layout"]
    s["isolators"]["list"] = [
        {"position": ["0.2 m", "0.3 m", "-0.3 m"]},
        {"position": ["2.4 m", "0.3 m", "-0.3 m"]},
        {"position": ["0.2 m", "3.9 m", "-0.3 m"], "preset": "wobbly"},
        {"position": ["2.4 m", "3.9 m", "-0.3 m"]},
    ]
    write(tmp_path / "scene.yaml", s)
    path = write(tmp_path / "study.yaml", {"name": "s", "scene_file": "scene.yaml"})
    line = assert_one_line_error(invoke("run", str(path), "-o", str(tmp_path / "out.nc")))
    assert line.startswith("error: scene.isolators.list[2].preset: ") and "mounts" not in line

    path = study(tmp_path, design={"type": "lhs", "samplez": 3})
    line = assert_one_line_error(invoke("run", str(path), "-o", str(tmp_path / "out.nc")))
    assert line == "error: design.samplez: unknown key"


def test_run_has_the_case_limit_of_submit(tmp_path: Path) -> None:
    # 3 x 4 = 12 cases against a limit of 10: the same refusal, word for word, as the service gives
    path = study(
        tmp_path,
        parameters=[
            {"path": "isolators.preset", "values": ["active", "air", "elastomer"]},
            {"path": "stages.y.profile.acceleration", "range": {"start": "0.5 g", "stop": "2 g", "num": 4}},
        ],
    )
    with pytest.raises(DefinitionError) as served:
        check_definition(read_study_file(path), max_cases=10)
    r = invoke("run", str(path), "-o", str(tmp_path / "out.nc"), env={"ISOLAB_MAX_CASES": "10"})
    line = assert_one_line_error(r, "12 cases", "limit of 10 (ISOLAB_MAX_CASES)")
    assert line == f"error: parameters: {served.value.details[0]['msg']}"
    r = invoke("run", str(path), "-o", str(tmp_path / "out.nc"), env={"ISOLAB_MAX_CASES": "ten"})
    assert_one_line_error(r, "ISOLAB_MAX_CASES must be an integer")


def test_run_given_a_scene_says_to_simulate_it(tmp_path: Path) -> None:
    path = write(tmp_path / "scene.yaml", scene())
    r = invoke("run", str(path), "-o", str(tmp_path / "out.nc"))
    assert_one_line_error(r, f"this is a scene: use `isolab simulate {path}`")


# ------------------------------------------------------------------------------------- isolab simulate
def test_simulate_errors_are_one_line(tmp_path: Path) -> None:
    s = scene()
    s["stages"][0]["mass"] = "-3 kg"
    line = assert_one_line_error(invoke("simulate", str(write(tmp_path / "bad.yaml", s))))
    assert line == "error: stages.y.mass: Input should be greater than 0"
    assert_one_line_error(invoke("simulate", str(tmp_path / "absent.yaml")), "absent.yaml: no such file")
    path = study(tmp_path)
    assert_one_line_error(
        invoke("simulate", str(path)), f"this is a study: use `isolab run {path} -o OUT.nc`"
    )
    write(tmp_path / "odd.yaml", {"machine": "9**9**9 kg"})  # refused before the units parser runs it
    assert_one_line_error(invoke("simulate", str(tmp_path / "odd.yaml")), "machine: ")


def test_messages_name_stages_and_keys_as_the_file_writes_them() -> None:
    names = ["y", "x"]
    assert in_user_words("stages[1].parent: no stage", names) == "stages.x.parent: no stage"
    assert in_user_words("invalid: stages.0.mass: must", names) == "invalid: stages.y.mass: must"
    assert in_user_words("isolators.mounts[2].k: bad; design_spec.samples", names) == (
        "isolators.list[2].k: bad; design.samples"
    )
    assert in_user_words("stages[5].mass", names) == "stages[5].mass"  # no such stage: as it was
    assert in_user_words("the mounts' centre", names) == "the mounts' centre"  # prose stays prose
    # a name two stages share does not say which: the index stays
    assert in_user_words("stages[1].name: 'y' is taken", ["y", None]) == "stages[1].name: 'y' is taken"


# ----------------------------------------------------------------------------------- the compile notice
def test_simulate_says_when_it_compiles(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = write(tmp_path / "scene.yaml", scene())
    monkeypatch.setattr("isolab.studies.run.kernel_cache.kernels_cached", lambda integrators, **_: False)
    r = invoke("simulate", str(path))
    assert r.exit_code == 0, r.output
    assert r.stderr.splitlines() == [local_commands.COMPILING] and "ok" in r.stdout
    monkeypatch.setattr("isolab.studies.run.kernel_cache.kernels_cached", lambda integrators, **_: True)
    r = invoke("simulate", str(path))
    assert r.exit_code == 0 and r.stderr == ""


def test_simulate_asks_for_its_own_pair(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # cached drivers per method and level: the notice asks about the pair the scene runs at, so a cache
    # that holds ltv/rk4 alone does not make a warm ltv/rk4 run say it compiles; and about the general
    # observer's driver only where the run calls it (a recorded case for the plot, a moving floor)
    path = write(tmp_path / "scene.yaml", scene())
    asked = []
    monkeypatch.setattr(
        "isolab.studies.run.kernel_cache.kernels_cached",
        lambda integrators, fidelity=None, general=True: (
            asked.append((list(integrators), fidelity, general)) or True
        ),
    )
    r = invoke("simulate", str(path), "--fidelity", "lti", "--integrator", "exact")
    assert r.exit_code == 0, r.output
    r = invoke("simulate", str(path), "--plot", str(tmp_path / "p.png"))
    assert r.exit_code == 0, r.output
    moving = write(
        tmp_path / "moving.yaml",
        scene() | {"floor": {"sine": {"amplitude": ["1 um", 0, 0], "frequency": ["20 Hz", 0, 0]}}},
    )
    r = invoke("simulate", str(moving))
    assert r.exit_code == 0, r.output
    assert asked == [(["exact"], "lti", False), (["exact"], "lti", True), (["exact"], "lti", True)]
    mapped, general = entry_kernels("rk4", "ltv")
    assert entry_kernels("rk4", "ltv", general=False) == [mapped] and len(entry_kernels("exact", "lti")) == 2
    assert len(entry_kernels("rk4")) == 5 and len(entry_kernels("euler", general=False)) == 3
    assert mapped is not general and mapped is not entry_kernels("rk4", "lti")[0]


def test_kernels_cached_reads_the_numba_index(tmp_path: Path) -> None:
    # a kernel of its own, in a module of its own: not cached until its first call compiles it
    name = f"kernel_{uuid.uuid4().hex}"
    (tmp_path / f"{name}.py").write_text(
        textwrap.dedent(
            """
            from numba import njit

            @njit(cache=True)
            def plus_one(x):
                return x + 1
            """
        )
    )
    sys.path.insert(0, str(tmp_path))
    try:
        module = __import__(name)
        assert not kernels_cached(kernels=[module.plus_one])
        assert module.plus_one(2) == 3
        assert kernels_cached(kernels=[module.plus_one])
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop(name, None)


def test_the_engine_kernels_are_not_cached_in_an_empty_cache(tmp_path: Path) -> None:
    code = (
        "from isolab.studies.run.kernel_cache import kernels_cached as k; print(k(['rk4']), k(['reference']))"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


# ------------------------------------------------------------------------------------- modes of files
@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_new_file_mode_follows_the_umask() -> None:
    old = os.umask(0o027)
    try:
        assert new_file_mode() == 0o640
        os.umask(0o022)
        assert new_file_mode() == 0o644
    finally:
        os.umask(old)


def test_copy_atomic_gives_the_umask_mode(tmp_path: Path, umask_022) -> None:
    source = tmp_path / "a.bin"
    source.write_bytes(b"abc")
    source.chmod(0o600)
    target = copy_atomic(source, tmp_path / "b.bin")
    assert target.read_bytes() == b"abc" and target.stat().st_mode & 0o777 == 0o644


def test_fetch_writes_with_the_umask_mode(tmp_path: Path, umask_022) -> None:
    def answer(request: httpx.Request) -> httpx.Response:
        assert request.url.path == "/studies/" + "a" * 32 + "/dataset"
        return httpx.Response(200, content=b"CDF\x01 netcdf bytes")

    api = Client("http://isolab.test")
    api._http = httpx.Client(base_url=api.base_url, transport=httpx.MockTransport(answer))
    with api:
        path = api.download("a" * 32, tmp_path / "study.nc")
    assert path.read_bytes() == b"CDF\x01 netcdf bytes" and path.stat().st_mode & 0o777 == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["study.nc"]  # no temporary file left


@pytest.mark.slow  # a LocalCluster of its own
def test_run_writes_the_dataset_with_the_umask_mode(
    tmp_path: Path, umask_022, monkeypatch: pytest.MonkeyPatch
) -> None:
    asked = []
    monkeypatch.setattr(
        "isolab.studies.run.kernel_cache.kernels_cached",
        lambda integrators, **_: asked.append(integrators) or False,
    )
    path = study(tmp_path)
    out = tmp_path / "out.nc"
    r = invoke("run", str(path), "-o", str(out), "--workers", "1")
    assert r.exit_code == 0, r.output
    assert "2 cases in" in r.stdout and out.stat().st_mode & 0o777 == 0o644
    # the study's integrator, and the reference that measures the dataset's error
    assert asked == [["exact", "reference"]] and r.stderr.splitlines()[0] == local_commands.COMPILING


def test_run_asks_about_the_general_observer_where_a_sampled_case_needs_it(tmp_path: Path) -> None:
    # the notice of `isolab run` asks about the general observer's driver only where a case the run
    # samples needs it: a still floor under every case does not, a floor amplitude a range spans does
    from isolab.studies import general_observer_called
    from isolab.studies.inputs.file_checks import check_study_file

    still = check_study_file(study(tmp_path))
    assert not local_commands.general_observer_sampled(still)
    amplitudes = {"path": "floor.sine.amplitude.z", "values": [k * 1e-8 for k in range(41)]}  # 0 first
    (tmp_path / "scene.yaml").write_text(
        yaml.safe_dump(scene() | {"floor": {"sine": {"amplitude": [0, 0, 0], "frequency": ["7 Hz"] * 3}}})
    )
    data = {"name": "shaking", "scene_file": "scene.yaml", "parameters": [amplitudes]}
    shaking = check_study_file(write(tmp_path / "shaking.yaml", data))
    assert shaking.n_cases == 41 and local_commands.general_observer_sampled(shaking)
    assert not general_observer_called(shaking.batch([0]))  # its first case alone would not say so
