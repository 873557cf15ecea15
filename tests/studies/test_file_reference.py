"""The study-file reference (docs/study-files.md) and the JSON Schema of study and scene files.

The document is generated from the models: it must equal what the generator makes now. The published
schema must accept every shipped example, refuse a misspelt key and carry the accepted ranges the models
check, and every design type must have an example that is a valid study.
"""

from __future__ import annotations

import copy
import difflib
import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from pydantic import ValidationError

from isolab.studies.authoring import file_reference as ref
from isolab.studies.inputs.schema import (
    MAX_SPAN,
    MAX_STAGE_MASS,
    MIN_SPAN,
    MIN_STAGE_MASS,
    Scene,
)
from isolab.studies.inputs.study import Study

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "study-files.md"
EXAMPLES = sorted((ROOT / "studies" / "examples").glob("*.yaml"))


@pytest.fixture(scope="module")
def study_schema() -> dict[str, Any]:
    return ref.study_json_schema()


@pytest.fixture(scope="module")
def scene_schema() -> dict[str, Any]:
    return ref.scene_json_schema()


def errors(schema: dict[str, Any], instance: Any) -> list[str]:
    """``path: message`` of every error, those of the branches of an anyOf (``x | None``) included."""
    validator = jsonschema.Draft7Validator(schema)
    out, stack = [], list(validator.iter_errors(instance))
    while stack:
        e = stack.pop()
        out.append(f"{'.'.join(map(str, e.absolute_path))}: {e.message}")
        stack.extend(e.context or [])
    return out


def is_study(data: dict[str, Any]) -> bool:
    return "scene" in data or "scene_file" in data


def test_the_document_is_what_the_models_give() -> None:
    expected = ref.render()
    actual = DOC.read_text(encoding="utf-8") if DOC.is_file() else ""
    if actual != expected:
        diff = "".join(
            list(
                difflib.unified_diff(
                    actual.splitlines(keepends=True),
                    expected.splitlines(keepends=True),
                    "docs/study-files.md",
                    "generated",
                )
            )[:40]
        )
        pytest.fail(
            "docs/study-files.md is out of date with the models: regenerate it with `make docs` "
            f"(python -m isolab.studies.authoring.file_reference > docs/study-files.md)\n{diff}"
        )


def test_the_schemas_name_their_dialect_address_and_title(study_schema: dict, scene_schema: dict) -> None:
    for schema, path, title in (
        (study_schema, "/schemas/study.json", "isolab study file"),
        (scene_schema, "/schemas/scene.json", "isolab scene file"),
    ):
        assert schema["$schema"] == "http://json-schema.org/draft-07/schema#"
        assert schema["$id"] == f"http://127.0.0.1:8000{path}"
        assert schema["title"] == title
        jsonschema.Draft7Validator.check_schema(schema)
    assert ref.study_json_schema("http://lab:9000/")["$id"] == "http://lab:9000/schemas/study.json"


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_file_is_valid_against_the_published_schema(
    path: Path, study_schema: dict, scene_schema: dict
) -> None:
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    if not is_study(data):
        assert errors(scene_schema, data) == []
        return
    assert errors(study_schema, data) == []
    if "scene_file" in data:  # and as the service receives it: the scene inline
        inline = {k: v for k, v in data.items() if k != "scene_file"}
        inline["scene"] = yaml.safe_load((path.parent / data["scene_file"]).read_text(encoding="utf-8"))
        assert errors(study_schema, inline) == []


def test_a_misspelt_key_is_refused_where_it_is(study_schema: dict, scene_schema: dict) -> None:
    study = yaml.safe_load((ROOT / "studies/examples/isolator-comparison.yaml").read_text())
    typo = {**study, "desing": study["design"]}
    assert errors(study_schema, typo) == [": Additional properties are not allowed ('desing' was unexpected)"]

    scene = ref.example_scene_data()
    assert errors(scene_schema, scene) == []
    bad = copy.deepcopy(scene)
    bad["machine"]["block"]["densty"] = bad["machine"]["block"].pop("density")
    found = errors(scene_schema, bad)
    assert any(e.startswith("machine.block:") and "'densty' was unexpected" in e for e in found), found
    bad = copy.deepcopy(scene)
    bad["stages"][0]["profile"]["acceleraton"] = "1 g"
    assert any("'acceleraton'" in e for e in errors(scene_schema, bad))
    with pytest.raises(ValidationError):  # the models agree
        Scene.model_validate(bad)


def test_quantities_take_numbers_or_strings_within_the_models_ranges(scene_schema: dict) -> None:
    stage = scene_schema["definitions"]["Stage"]["properties"]["mass"]
    assert stage["x-dimension"] == "mass" and stage["x-unit"] == "kg"
    assert stage["minimum"] == MIN_STAGE_MASS and stage["maximum"] == MAX_STAGE_MASS
    assert stage["exclusiveMinimum"] == 0
    scene = ref.example_scene_data()
    for value, ok in (("1 t", True), (1000, True), (MAX_STAGE_MASS, True), (MAX_STAGE_MASS * 1.01, False)):
        data = copy.deepcopy(scene)
        data["stages"][0]["mass"] = value
        assert (errors(scene_schema, data) == []) is ok, value
        if not ok:  # the model refuses what the schema refuses
            with pytest.raises(ValidationError, match="must lie between"):
                Scene.model_validate(data)
    data = copy.deepcopy(scene)
    data["stages"][0]["mass"] = True
    assert errors(scene_schema, data) != []
    for home, ok in (([1.3, "600 mm", 0.47], True), ([1.3, 0.6], False), ([1.3, 0.6, 500.0], False)):
        data = copy.deepcopy(scene)
        data["stages"][0]["home"] = home  # a position: three coordinates, each within 100 m
        assert (errors(scene_schema, data) == []) is ok, home
    assert "prefixItems" not in json.dumps(scene_schema) and "$defs" not in json.dumps(scene_schema)


def test_the_document_states_the_ranges_and_units_the_models_check() -> None:
    text = DOC.read_text(encoding="utf-8")
    span = f"| `span_x` | length | m | required | {MIN_SPAN:g} to {MAX_SPAN:g} (the range the engine"
    assert span in text
    assert f"| `mass` | mass | kg | required | {MIN_STAGE_MASS:g} to {MAX_STAGE_MASS:g} " in text
    # the criteria block: any other key is a point
    assert "| `<point>` | [PointCriteria](#pointcriteria) |" in text
    assert "`stages.y.profile.acceleration` | `stage_y_acceleration` | acceleration | m/s^2 | > 0 |" in text


def test_no_model_takes_keys_the_schema_cannot_describe(study_schema: dict) -> None:
    """A model that accepts keys of the user's choosing needs an entry in EXTRA_KEYS; every other model
    refuses unknown keys (additionalProperties false)."""
    for name, node in study_schema["definitions"].items():
        if node.get("type") == "object" and "properties" in node:
            extra = node.get("additionalProperties")
            assert extra is False or isinstance(extra, dict), name


EXPECTED_CASES = {
    "grid": 12,
    "lhs": 200,
    "sobol": 256,
    "random": 100,
    "saltelli": 8 * 16 * (3 + 2),  # replicates x samples x (D + 2)
    "list": 3,
    "monte_carlo": 256,
}


@pytest.mark.parametrize("kind", ref.design_types())
def test_every_design_type_has_an_example_that_is_a_valid_study(kind: str, study_schema: dict) -> None:
    assert kind in ref.DESIGN_EXAMPLES, (
        f"design type {kind!r} has no example in studies/authoring/file_reference.py"
    )
    data = ref.design_example(kind)
    assert errors(study_schema, data) == []
    study = Study.model_validate(data)
    assert study.design_spec.type == kind
    if kind == "optimize":
        assert study.planned_cases == data["design"]["budget"] == 200
    else:
        assert study.n_cases == EXPECTED_CASES[kind]
