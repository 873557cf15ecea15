"""Damping per direction from a catalogue product: the catalogue's fields and their refusals, the mount's
viscous damping ``2 zeta sqrt(k m)`` per axis, the vertical mode's damping ratio in closed form, and a
product that gives one ratio for both directions running bit for bit as one ``zeta``."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from pydantic import ValidationError

from isolab.engine import model as engine_model
from isolab.engine.modal import modes
from isolab.studies.inputs.catalogues import Catalogue
from isolab.studies.inputs.study import scene_batch, validate_scene
from isolab.studies.units import STANDARD_GRAVITY
from tests.studies.test_sizing import CATALOGUE, QUARTER, SCENE

ZV, ZH = 0.20, 0.05


def on_product(**damping: float) -> dict:
    """SCENE standing on a copy of ``soft`` (2 Hz, 5-20 kN) with the given damping fields."""
    cat = copy.deepcopy(CATALOGUE)
    soft = next(p for p in cat["products"] if p["id"] == "soft")
    soft.pop("zeta")
    soft.update(damping)
    s = copy.deepcopy(SCENE)
    s["isolators"].update(model="soft", catalogue=cat)
    return s


def test_catalogue_takes_the_ratio_per_direction_and_names_a_missing_one() -> None:
    cat = Catalogue.model_validate(on_product(zeta_vertical=ZV, zeta_horizontal=ZH)["isolators"]["catalogue"])
    soft = cat.product("soft")
    assert (soft.zeta, soft.zeta_vertical, soft.zeta_horizontal) == (None, ZV, ZH)
    for damping, field in (({"zeta_vertical": ZV}, "zeta_horizontal"), ({}, "zeta")):
        with pytest.raises(ValidationError) as err:
            Catalogue.model_validate(on_product(**damping)["isolators"]["catalogue"])
        assert f"{field}: give the damping ratio" in str(err.value)
    with pytest.raises(ValidationError) as err:
        Catalogue.model_validate(on_product(zeta=0.1, zeta_horizontal=-0.1)["isolators"]["catalogue"])
    assert "products.3.zeta_horizontal" in str(err.value).replace("\n", ".")


def test_each_axis_gets_its_own_viscous_damping_and_the_bounce_mode_its_ratio() -> None:
    b, _ = scene_batch(validate_scene(on_product(zeta_vertical=ZV, zeta_horizontal=ZH)))
    k = (2 * math.pi * 2.0) ** 2 * QUARTER / STANDARD_GRAVITY  # 2 Hz at a quarter of the weight, N/m
    c = 2 * np.array([ZH, ZH, ZV]) * math.sqrt(k * QUARTER / STANDARD_GRAVITY)
    assert b.iso_c[0] == pytest.approx(np.tile(c, (4, 1)), rel=1e-12)
    # the vertical bounce of a symmetric base on four equal mounts: its own mode, damped at zeta_vertical
    m = modes(engine_model.mass_matrix(b), engine_model.stiffness_matrix(b), engine_model.damping_matrix(b))
    bounce = int(np.argmin(np.abs(m.frequency[0] - 2.0)))
    assert m.frequency[0, bounce] == pytest.approx(2.0, rel=1e-9)
    assert m.damping_ratio[0, bounce] == pytest.approx(ZV, rel=1e-9)


def test_one_ratio_both_ways_is_bit_identical_to_zeta_and_the_mounts_own_zeta_wins() -> None:
    same, plain = on_product(zeta_vertical=0.1, zeta_horizontal=0.1), on_product(zeta=0.1)
    a, _ = scene_batch(validate_scene(same))
    p, _ = scene_batch(validate_scene(plain))
    assert np.array_equal(a.iso_c, p.iso_c) and np.array_equal(a.iso_k, p.iso_k)
    own = on_product(zeta_vertical=ZV, zeta_horizontal=ZH)
    own["isolators"]["zeta"] = 0.1  # written on the mount: every axis
    o, _ = scene_batch(validate_scene(own))
    assert np.array_equal(o.iso_c, p.iso_c)
