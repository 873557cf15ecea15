"""The bodies of ``POST /comparisons`` with a catalogue: the request's catalogue fields, the recommended
product and the catalogue block of the answer (SI; costs in the catalogue's currency)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from isolab.service.api.schemas import EXAMPLE_COMPARISON, Comparison, ComparisonRequest, Recommendation
from isolab.studies.inputs.catalogues import DEFAULT_LOAD_MARGIN, CatalogueFormat, LoadMargin, PerCornerCounts

MAX_CATALOGUE_TEXT = 2_000_000
"""Most characters of a catalogue file read by ``POST /catalogues/read``."""
EXAMPLE_CATALOGUE_CSV = (
    "id,type,maker,series,rated_load.min [kN],rated_load.max [kN],f_vertical [Hz],f_horizontal [Hz],zeta,"
    "effective_area [cm^2],price [EUR]\n"
    "air-40,air,Maker,Series A,10,40,2.5,4,0.12,800,2600\n"
)

EXAMPLE_CATALOGUE_COMPARISON: dict[str, Any] = {
    "scene": EXAMPLE_COMPARISON["scene"],
    "catalogue": "representative",
    "per_corner": [1, 2],
    "simulation": {"duration": "3 s"},
}
"""The article's scriber on each product of the shipped catalogue that carries its loads."""


class CatalogueComparisonRequest(ComparisonRequest):
    """One scene under several isolator types, or (with ``catalogue``) under each product of a catalogue
    whose rated range carries the scene's static loads."""

    model_config = ConfigDict(
        extra="forbid", json_schema_extra={"examples": [EXAMPLE_COMPARISON, EXAMPLE_CATALOGUE_COMPARISON]}
    )

    catalogue: dict[str, Any] | str | None = Field(
        None,
        description="compare the products of this catalogue instead of the generic types: inline (as in a "
        "catalogue file: name, currency, products) or a shipped one by name (representative); "
        "isolator_types then picks the products' types",
    )
    margin: LoadMargin = Field(
        DEFAULT_LOAD_MARGIN,
        description="with a catalogue: each isolator's static load may change by this fraction either way "
        "and stay in its rated range, 1",
    )
    per_corner: PerCornerCounts | None = Field(
        None,
        description="with a catalogue: how many isolators side by side a mount position may take (default: "
        "the scene's isolators.per_corner, else [1])",
    )


class ProductRecommendation(Recommendation):
    """The one isolator type (with a catalogue: the one product) to buy, and why."""

    product: str | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="with a catalogue: the cheapest priced product that meets every criterion (with "
        "tolerances: reaches require), else the unpriced one with the largest smallest margin",
    )
    basis: str | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="probability: on tolerances; with a catalogue cost (a priced product) or margin",
    )


class ProductComparison(Comparison):
    """A side-by-side table: one row per isolator type, or with a catalogue per product id."""

    recommendation: ProductRecommendation
    catalogue: dict[str, Any] | None = Field(
        None,
        exclude_if=lambda v: v is None,
        description="with a catalogue: its name, currency, the load margin and counts asked for, each "
        "mount's static_load (N), and per product (products) its counts per mount, load_per_isolator (N), "
        "load_margin (1), pressure (Pa), cost, and verdict (compared, or skipped with the reason)",
    )


class CatalogueFile(BaseModel):
    """A catalogue file's text, as a page reads an uploaded file: the body of ``POST /catalogues/read``."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [{"text": EXAMPLE_CATALOGUE_CSV, "format": "csv", "name": "mine"}]},
    )

    text: str = Field(max_length=MAX_CATALOGUE_TEXT, description="the file's contents")
    format: CatalogueFormat = Field(
        "yaml",
        description="yaml or json (a mapping: name, currency, products), or csv (a header row of product "
        "fields with their units in brackets, one product a row; the unit of price is the currency)",
    )
    name: str = Field("catalogue", min_length=1, max_length=200, description="the name of a CSV catalogue")


class CatalogueRead(BaseModel):
    """A catalogue file, read and checked: as a comparison or a sizing takes it inline."""

    catalogue: dict[str, Any] = Field(
        description="the catalogue (name, currency, products), every quantity in SI: the catalogue field of "
        "POST /comparisons or POST /sizings"
    )
    products: list[str] = Field(description="the products' ids, in the file's order")
