"""The reference of study and scene files: every key, and the JSON Schema editors check the files with.

Both are made from the pydantic models (:class:`studies.inputs.study.Study`,
:class:`studies.inputs.schema.Scene` and everything below them), so a field added to a model appears in
both without further work:

- :func:`study_json_schema` and :func:`scene_json_schema` (:mod:`studies.authoring.json_schemas`): the
  JSON Schema (draft-07) of a study file and of a scene file, published by the service at
  ``GET /schemas/study.json`` and ``GET /schemas/scene.json``.
- :func:`render` (:mod:`studies.authoring.reference_markdown`): ``docs/study-files.md``, one table per
  model, the parameter paths a study may vary and every design type with an example
  (:mod:`studies.authoring.reference_examples`).

Regenerate the document with ``make docs`` (``python -m isolab.studies.authoring.file_reference >
docs/study-files.md``); a test fails while it differs from :func:`render`.
"""

from __future__ import annotations

import sys

from isolab.studies.authoring.json_schemas import (
    DEFAULT_BASE_URL,
    SCENE_SCHEMA_PATH,
    SCHEMA_DIALECT,
    STUDY_SCHEMA_PATH,
    scene_json_schema,
    study_json_schema,
)
from isolab.studies.authoring.reference_examples import (
    DESIGN_EXAMPLES,
    EXAMPLE_SCENE,
    design_example,
    design_types,
    example_scene_data,
)
from isolab.studies.authoring.reference_markdown import render

__all__ = [
    "DEFAULT_BASE_URL",
    "DESIGN_EXAMPLES",
    "EXAMPLE_SCENE",
    "SCENE_SCHEMA_PATH",
    "SCHEMA_DIALECT",
    "STUDY_SCHEMA_PATH",
    "design_example",
    "design_types",
    "example_scene_data",
    "main",
    "render",
    "scene_json_schema",
    "study_json_schema",
]


def main() -> None:
    """Print :func:`render` (``python -m isolab.studies.authoring.file_reference > docs/study-files.md``)."""
    sys.stdout.write(render())


if __name__ == "__main__":
    main()
