"""The common units read without the units parser give exactly what the parser gives."""

from __future__ import annotations

import subprocess
import sys

import pytest

from isolab.studies import units
from isolab.studies.units import COMMON_UNITS, parsed_unit_factor, parsed_unit_problem, to_si


@pytest.mark.parametrize(("unit", "dimension"), sorted(COMMON_UNITS))
def test_a_common_unit_is_the_parsers_float_to_the_last_bit(unit: str, dimension: str) -> None:
    factor = COMMON_UNITS[(unit, dimension)]
    assert parsed_unit_factor(unit, dimension) == factor
    assert parsed_unit_problem(unit) is None
    for number in (1.0, 0.37, 2.5e-3, -1234.5):
        text = f"{number!r} {unit}"
        assert to_si(text, dimension, "x") == units._to_si(text, dimension, "x", fast=False)


def test_gravity_and_percent_keep_their_meaning() -> None:
    assert to_si("2 g", "acceleration", "a") == 2 * units.STANDARD_GRAVITY
    assert to_si("2 g", "mass", "m") == pytest.approx(0.002)  # the gram, read by the parser
    assert to_si("5 %", "dimensionless", "zeta") == pytest.approx(0.05)
    with pytest.raises(ValueError, match="expected a length"):
        to_si("3 Hz", "length", "span")


def test_a_scene_in_common_units_loads_without_the_units_parser() -> None:
    code = (
        "import sys; from isolab.studies.inputs.study import load_scene; "
        "load_scene('studies/examples/article-scriber.yaml'); print('pint' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
