"""Studies as text (isolab.studies.authoring.authoring) and modes named by their motion
(isolab.studies.answers.history):
what the web page's editor, study and case views stand on."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from isolab.studies.answers.history import mode_name
from isolab.studies.authoring.authoring import (
    MAX_DEPTH,
    ExampleNotFound,
    check_text,
    definition_yaml,
    design_summary,
    example_names,
    example_text,
)
from isolab.studies.inputs.definitions import DefinitionError, check_definition, stored_definition


def problems(text: str) -> list[dict]:
    with pytest.raises(DefinitionError) as err:
        check_text(text, max_cases=1000, workers=2)
    return err.value.details


def line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.split("\n")) if needle in line) + 1


def test_examples_are_the_study_files_with_their_scene_inlined_and_comments_kept() -> None:
    assert "isolator-comparison" in example_names()
    assert "article-scriber" not in example_names()  # a scene file, not a study
    text = example_text("isolator-comparison")
    assert "scene_file" not in text and "# Which isolator type" in text
    data = yaml.safe_load(text)
    assert data["scene"]["stages"][0]["name"] == "y"
    with pytest.raises(ExampleNotFound):
        example_text("../store")


def test_a_good_text_is_counted_and_timed_without_being_stored() -> None:
    answer = check_text(example_text("isolator-comparison"), max_cases=1000, workers=2)
    assert answer["n_cases"] == 12
    assert answer["parameters"] == ["isolator_type", "stage_y_acceleration"]
    assert 0 < answer["estimated_seconds"] < 60
    assert answer["definition"]["parameters"][1]["range"]["start"] == "0.5 g"  # as written


def test_each_problem_is_placed_at_its_line() -> None:
    text = example_text("isolator-comparison")
    bad = text.replace("num: 4", "num: 0").replace("mass: 1000 kg", "mass: -1000 kg")
    found = {d["line"]: d for d in problems(bad)}
    assert found[line_of(bad, "num: 0")]["loc"] == ["body", "text", "parameters", 1, "range", "num"]
    assert found[line_of(bad, "mass: -1000 kg")]["loc"][-1] == "mass"


def test_a_problem_named_only_in_its_message_is_placed_too() -> None:
    text = example_text("isolator-comparison").replace("path: isolators.preset", "path: isolators.nonsense")
    (d,) = problems(text)
    assert d["loc"][2:] == ["parameters", 0, "path"] and d["line"] == line_of(text, "isolators.nonsense")


def test_yaml_errors_aliases_depth_and_non_mappings_are_problems_not_crashes() -> None:
    (d,) = problems("name: x\nparameters: [1, 2\nscene: {}\n")
    assert d["type"] == "yaml_error" and d["line"] == 3
    (d,) = problems("name: x\na: &a [1, *a]\n")  # an alias inside the node it names: infinite data
    assert "inside the node it names" in d["msg"]
    # aliases of aliases: ten lines that would expand to 1.2e10 values, counted without expanding them:
    # root, 2 + 10 keys and values, a0..a9 of 11, 111, ... 11,111,111,111 nodes
    bomb = "name: x\na0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n" + "".join(
        f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 10)}]\n" for k in range(1, 10)
    )
    (d,) = problems(bomb)
    assert d["type"] == "too_large" and "12,345,679,023 values" in d["msg"] and "500,000" in d["msg"]
    (d,) = problems("[" * (MAX_DEPTH + 5) + "]" * (MAX_DEPTH + 5))
    assert "deeper" in d["msg"]
    (d,) = problems("- just\n- a list\n")
    assert "mapping" in d["msg"]
    (d,) = problems("name: x\nwhen: 2026-11-24\n")
    assert "value a study cannot have" in d["msg"]


def test_yaml_aliases_are_accepted_as_the_command_line_accepts_them() -> None:
    """scriber-criteria.yaml gives its floor spectrum once (``&site``) and repeats it per axis (``*site``):
    the text checks as the file loads, each axis the same spectrum."""
    text = example_text("scriber-criteria")
    assert "*site" in text
    answer = check_text(text, max_cases=1000, workers=2)
    spectrum = answer["definition"]["floor"]["spectrum"]
    assert spectrum["x"] == spectrum["y"] == spectrum["z"] == yaml.safe_load(text)["floor"]["spectrum"]["x"]
    assert answer["n_cases"] == 3


def test_a_stored_definition_reads_back_as_yaml() -> None:
    definition = check_text(example_text("isolator-comparison"), 1000, 1)["definition"]
    assert yaml.safe_load(definition_yaml(definition)) == definition


@pytest.mark.parametrize(
    ("energy", "name"),
    [
        ([0, 0, 1, 0, 0, 0], "heave"),
        ([0.85, 0, 0, 0, 0.15, 0], "surge"),
        ([0, 0.3, 0, 0.7, 0, 0], "pitch + sway"),
        ([0, 0, 0, 0, 0.9, 0.1], "roll"),
        ([0, 0, 0, 0, 0, 1], "yaw"),
        ([np.nan] * 6, ""),
    ],
)
def test_modes_are_named_by_their_dominant_motion(energy: list[float], name: str) -> None:
    assert mode_name(np.array(energy)) == name


def test_a_stored_study_reads_back_in_its_authors_units_and_checks_again() -> None:
    text = example_text("isolator-comparison").replace(
        "range: {start: 0.5 g, stop: 2 g, num: 4}",
        "range: {start: 500 cm/s^2, stop: 2000 cm/s^2, num: 3, scale: log}",
    )
    study = check_definition(check_text(text, 1000, 1)["definition"])
    row = {"definition": stored_definition(study)}
    design = design_summary(row)
    accel = design["parameters"][1]
    assert accel["name"] == "stage_y_acceleration" and accel["scale"] == "log"
    assert accel["display_unit"] == "cm/s^2" and accel["display_scale"] == pytest.approx(0.01)
    assert accel["range"]["start"] == "500 cm/s^2"  # as written
    assert design["parameters"][0]["categorical"] and design["n_cases"] == 9
    # the stored definition, as YAML, is a study the editor can check and submit again
    assert check_text(definition_yaml(row["definition"]), 1000, 1)["n_cases"] == 9
