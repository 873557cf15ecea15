"""The examples the study-file reference is written on: the example scene, a variant of it that has the
paths the example lacks, and one ``parameters:``/``design:`` example per design type."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import yaml

from isolab.studies.inputs.schema import DesignSpec, Scene
from isolab.studies.inputs.study import load_scene

EXAMPLES_DIR = Path(__file__).resolve().parent.parent / "examples"
EXAMPLE_SCENE = EXAMPLES_DIR / "article-scriber.yaml"
"""The scene whose parameter paths the reference lists, and which the design examples run on."""

DESIGN_EXAMPLES: dict[str, tuple[str, str]] = {
    "grid": (
        "Full factorial: every combination of the parameters' `values` (or `range` with `num` levels). "
        "The dataset has one dimension per parameter.",
        """\
parameters:
  - path: isolators.preset
    values: [active, air, elastomer]
  - path: stages.y.profile.acceleration
    range: {start: 0.5 g, stop: 2 g, num: 4}
design:
  type: grid                   # 3 x 4 = 12 cases
""",
    ),
    "lhs": (
        "Latin hypercube of `samples` cases over the parameters' ranges (each range cut into `samples` "
        "strata, each hit once); the same `seed` gives the same cases.",
        """\
parameters:
  - path: isolators.f_vertical
    range: {start: 1.5 Hz, stop: 6 Hz, scale: log}
  - path: stages.y.mass
    range: {start: 500 kg, stop: 1500 kg}
design:
  type: lhs
  samples: 200
  seed: 1
""",
    ),
    "sobol": (
        "Scrambled Sobol' sequence of `samples` cases (best balanced when `samples` is a power of 2).",
        """\
parameters:
  - path: isolators.zeta
    range: {start: 2 %, stop: 40 %}
  - path: isolators.layout.span_y
    range: {start: 2.4 m, stop: 4.0 m}
design:
  type: sobol
  samples: 256
""",
    ),
    "random": (
        "Independent uniform samples: `samples` cases; a categorical parameter draws from its `values`.",
        """\
parameters:
  - path: isolators.preset
    values: [air, elastomer]
  - path: stages.y.profile.acceleration
    range: {start: 0.5 g, stop: 2 g}
design:
  type: random
  samples: 100
  seed: 7
""",
    ),
    "saltelli": (
        "Saltelli's scheme for Sobol' sensitivity indices (`isolab sensitivity`): `samples` is the base "
        "sample N, the study runs N (D + 2) cases for D parameters (N (2D + 2) with `second_order: true`), "
        "times `replicates`: R independent copies of the design, whose spread gives the indices' 95 % "
        "intervals. Ranges only: no categorical parameter.",
        """\
parameters:
  - path: isolators.f_vertical
    range: {start: 1.5 Hz, stop: 6 Hz, scale: log}
  - path: isolators.zeta
    range: {start: 5 %, stop: 40 %}
  - path: stages.y.mass
    range: {start: 500 kg, stop: 1500 kg}
design:
  type: saltelli
  samples: 16                  # per replicate: 16 x (3 + 2) = 80 cases
  replicates: 8                # 8 x 80 = 640 cases
""",
    ),
    "list": (
        "The cases one by one: each entry of `cases` maps every parameter's name to its value (units "
        "allowed). Parameters then need neither `values` nor `range`.",
        """\
parameters:
  - path: isolators.preset                 # name: isolator_type
  - path: stages.y.profile.acceleration    # name: stage_y_acceleration
design:
  type: list
  cases:
    - {isolator_type: air, stage_y_acceleration: 1 g}
    - {isolator_type: elastomer, stage_y_acceleration: 1.5 g}
    - {isolator_type: active, stage_y_acceleration: 2 g}
""",
    ),
    "optimize": (
        "An optimiser (pymoo) picks the cases generation by generation, at most `budget` in all: "
        "`objective` is `minimize <output>` or `maximize <output>` (a list of them for a Pareto front), "
        "`constraints` the word `criteria` (every criterion met) or `<output> <= <value>` with units.",
        """\
parameters:
  - path: isolators.f_vertical
    range: {start: 1.5 Hz, stop: 6 Hz}
  - path: isolators.zeta
    range: {start: 5 %, stop: 40 %}
design:
  type: optimize
  objective: minimize settling_time
  constraints: ["min_isolator_load >= 0 N"]
  budget: 200
  population: 20
""",
    ),
    "monte_carlo": (
        "`samples` cases drawn from the `tolerances:` block (the study's, else the scene's): each path's "
        "spread about its nominal value (a parameter's one value, else the scene's). `%` is a share of "
        "the nominal value; `within` bounds a uniform spread and truncates a normal or lognormal one. "
        "`sampling: sobol` (default, a scrambled Sobol' sequence) or `random`. The dataset stores "
        "`probability_meets_criteria` and each criterion's failure probability, with their 95 % "
        "Clopper-Pearson intervals.",
        """\
criteria:
  isolators: {no_liftoff: true, max_deflection: 10 mm}
parameters:
  - {path: isolators.f_vertical, values: [3.5 Hz]}   # the nominal design
tolerances:
  isolators.f_vertical: {distribution: normal, sigma: 10 %, within: 20 %}
  isolators.zeta: {distribution: uniform, within: 20 %}
  stages.y.mass: {distribution: lognormal, sigma: 5 %}
  machine.block.density: {distribution: uniform, within: 100 kg/m^3}
design:
  type: monte_carlo
  samples: 256
  seed: 1
""",
    ),
}
"""Per design type: what it does and a ``parameters:``/``design:`` example (on :data:`EXAMPLE_SCENE`)."""

VARIANT_SCENE_CHANGES = """\
machine:
  mass: 10000 kg
  cg: [1.3 m, 2.1 m, 0.17 m]
  inertia_diagonal: [1.5e4 kg m^2, 5.7e3 kg m^2, 2e4 kg m^2]
isolators:
  preset: air
  list:
    - {position: [0.2 m, 0.3 m, -0.33 m], k: [2e5 N/m, 2e5 N/m, 1.2e6 N/m]}
    - {position: [2.4 m, 0.3 m, -0.33 m]}
    - {position: [2.4 m, 3.9 m, -0.33 m]}
    - {position: [0.2 m, 3.9 m, -0.33 m]}
floor:
  sine: {amplitude: [0, 0, 2 um], frequency: [0, 0, 12 Hz]}
"""
"""What the reference's second scene changes in :data:`EXAMPLE_SCENE`: a machine by mass, an explicit
list of mounts and a sine floor, whose parameter paths the example scene has not."""
VARIANT_STAGE_PROFILES = {
    "y": {
        "type": "sequence",
        "segments": [
            {"move": "1.5 m", "velocity": "2 m/s", "acceleration": "1 g", "jerk": "100 m/s^3"},
            {"dwell": "0.2 s"},
            {"move": "-1.5 m", "velocity": "2 m/s", "acceleration": "1 g"},
        ],
    },
    "x": {
        "type": "scurve",
        "travel": "0.3 m",
        "velocity": "1 m/s",
        "acceleration": "1 g",
        "jerk": "50 m/s^3",
    },
}


def example_scene_data() -> dict[str, Any]:
    """The example scene (:data:`EXAMPLE_SCENE`) as written, a fresh dict."""
    return yaml.safe_load(EXAMPLE_SCENE.read_text(encoding="utf-8"))


def variant_scene(base: dict[str, Any]) -> Scene:
    """The scene ``base`` (the example scene's data) with :data:`VARIANT_SCENE_CHANGES` and
    :data:`VARIANT_STAGE_PROFILES` applied, validated."""
    data = copy.deepcopy(base)
    data.update(yaml.safe_load(VARIANT_SCENE_CHANGES))
    for stage in data["stages"]:
        stage["profile"] = copy.deepcopy(VARIANT_STAGE_PROFILES[stage["name"]])
    return load_scene(data)


def design_types() -> list[str]:
    """The design types :class:`~studies.inputs.schema.DesignSpec` accepts, in the order it lists them."""
    node = DesignSpec.model_json_schema()["properties"]["type"]
    return list(node["enum"]) if "enum" in node else [node["const"]]


def design_example(kind: str) -> dict[str, Any]:
    """The example study of design type ``kind`` on the example scene (a dict ready to validate)."""
    _, text = DESIGN_EXAMPLES[kind]
    return {"name": f"{kind}-example", "scene": example_scene_data(), **yaml.safe_load(text)}
