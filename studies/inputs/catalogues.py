"""Isolator catalogues: products with their rated load range and the figures a scene's mount takes.

A catalogue is a YAML (or JSON) file of products, each quantity written with its unit as in the scene
files (``rated_load: {min: 8 kN, max: 30 kN}``; a load may also be written as a mass, ``2000 kg``, read
as its weight under standard gravity). A mount names a product by ``model: <id>``; the scene then uses
the product's natural frequencies and damping ratio (:func:`product_figures`), as if they were written
on the mount. The shipped catalogue (:data:`SHIPPED_CATALOGUES`) holds representative figures from
public datasheets; users bring their own.
"""

from __future__ import annotations

import difflib
import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StrictFloat,
    StrictInt,
    field_validator,
    model_validator,
)

from isolab.studies.units import (
    STANDARD_GRAVITY,
    Area,
    Dimensionless,
    Frequency,
    Length,
    Pressure,
    Time,
    to_si,
)

CATALOGUE_DIR = Path(__file__).resolve().parent.parent / "catalogues"
"""Where the shipped catalogues live (package data of ``isolab.studies``)."""
SHIPPED_CATALOGUES: dict[str, Path] = {"representative": CATALOGUE_DIR / "representative.yaml"}
"""The catalogues installed with isolab, by name."""
DEFAULT_CATALOGUE = "representative"
"""The catalogue a ``model:`` reads when the scene names none."""
MAX_PRODUCTS = 1000
"""Most products of one catalogue."""
MAX_PER_CORNER = 8
"""Most isolators one mount position may take side by side."""
DEFAULT_LOAD_MARGIN = 0.10
"""The load margin a sizing keeps when none is asked for: each isolator's static load may change by 10 %
either way and stay in its product's rated range."""
PerCornerCounts = Annotated[
    list[Annotated[StrictInt, Field(ge=1, le=MAX_PER_CORNER)]],
    Field(min_length=1, max_length=MAX_PER_CORNER),
]
"""How many isolators side by side a mount position may take, each a choice (of 1 to MAX_PER_CORNER)."""
LoadMargin = Annotated[StrictFloat, Field(ge=0.0, le=0.9)]
"""A load margin, 1: the fraction by which each isolator's static load may change either way and stay in its
product's rated range."""
CATALOGUE_SUFFIXES = (".yaml", ".yml", ".json", ".csv")
"""Endings of a catalogue file name (a ``catalogue:`` naming no shipped catalogue but a file)."""
CatalogueFormat = Literal["yaml", "json", "csv"]
"""How a catalogue file is written (JSON is also read as YAML)."""

AXIS_DAMPING = ("zeta_vertical", "zeta_horizontal")
"""Damping ratios per direction a product (and a mount) may give besides ``zeta``."""

ProductId = Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$", max_length=64)]
"""A product's id: letters, digits and ``_ . + -``, starting with a letter or digit."""
IsolatorType = Literal["active", "air", "elastomer"]


def _load_in_newtons(value: Any) -> Any:
    """A load as a force (``25 kN``) or as the mass it carries (``2500 kg``: its standard weight), N."""
    if value is None:
        return value
    try:
        return to_si(value, "force", "load")
    except ValueError:
        if isinstance(value, str):
            try:
                return to_si(value, "mass", "load") * STANDARD_GRAVITY
            except ValueError:
                pass
        raise ValueError(f"expected a load in N (or a mass such as '2500 kg'), got {value!r}") from None


Load = Annotated[float, BeforeValidator(_load_in_newtons)]
"""A static load, N (a mass is read as its weight under standard gravity)."""


class CatalogueModel(BaseModel):
    """A block of a catalogue file: unknown keys are refused."""

    model_config = ConfigDict(extra="forbid")


class RatedLoad(CatalogueModel):
    """The static load range one isolator is rated for, N."""

    min: Annotated[Load, Field(ge=0)] = Field(description="smallest rated static load per isolator, N")
    max: Annotated[Load, Field(gt=0)] = Field(description="largest rated static load per isolator, N")

    @model_validator(mode="after")
    def _ordered(self) -> RatedLoad:
        if not self.max > self.min:
            raise ValueError(f"max: must exceed min ({self.min:.6g} N), got {self.max:.6g} N")
        return self


class Product(CatalogueModel):
    """One isolator product: what it carries, the figures it gives its load, and what it costs.

    ``f_vertical``, ``f_horizontal`` and ``zeta`` are the natural frequencies and the damping ratio the
    maker quotes at rated load (``zeta_vertical`` and ``zeta_horizontal`` where the datasheet gives the
    damping of each direction: either replaces ``zeta`` along its axes, and with both ``zeta`` may be left
    out); a mount naming the product uses them at whatever load it carries within
    the rated range (a levelled air spring keeps its frequency as its pressure follows the load).
    ``effective_area`` (air springs) gives the gauge pressure ``p = F / A`` at a load ``F``.
    """

    id: ProductId
    type: IsolatorType = Field(description="active, air or elastomer: the model a mount naming it runs")
    maker: str = Field(min_length=1, max_length=200)
    series: str = Field(min_length=1, max_length=200)
    source: str | None = Field(None, max_length=500, description="the datasheet the figures come from")
    note: str | None = Field(None, max_length=1000, description="how the figures were read")
    rated_load: RatedLoad
    f_vertical: Annotated[Frequency, Field(gt=0)] = Field(description="vertical natural frequency, Hz")
    f_horizontal: Annotated[Frequency, Field(gt=0)] = Field(description="horizontal natural frequency, Hz")
    zeta: Annotated[Dimensionless, Field(ge=0, le=2)] | None = Field(
        None, description="damping ratio of every axis, 1 (unless zeta_vertical and zeta_horizontal give it)"
    )
    zeta_vertical: Annotated[Dimensionless, Field(ge=0, le=2)] | None = Field(
        None, description="damping ratio along the vertical (the mount's own z), 1"
    )
    zeta_horizontal: Annotated[Dimensionless, Field(ge=0, le=2)] | None = Field(
        None, description="damping ratio along the horizontal (the mount's own x and y), 1"
    )
    stroke: Annotated[Length, Field(gt=0)] | None = Field(
        None, description="usable travel each way from the working height, m"
    )
    max_load: Annotated[Load, Field(gt=0)] | None = Field(
        None, description="largest load one isolator survives (static plus dynamic), N"
    )
    footprint: tuple[Annotated[Length, Field(gt=0)], Annotated[Length, Field(gt=0)]] | None = Field(
        None, description="[x, y] size of the base plate, m"
    )
    effective_area: Annotated[Area, Field(gt=0)] | None = Field(
        None, description="effective area of an air spring, m^2 (pressure = load / area)"
    )
    max_pressure: Annotated[Pressure, Field(gt=0)] | None = Field(
        None, description="largest gauge supply pressure, Pa"
    )
    price: Annotated[float, Field(ge=0)] | None = Field(None, description="price of one isolator")
    lead_time: Annotated[Time, Field(ge=0)] | None = Field(None, description="delivery time, s")

    @field_validator("f_vertical", "f_horizontal")
    @classmethod
    def _tested_frequency(cls, value: float) -> float:
        from isolab.studies.inputs.schema.fields import MAX_MOUNT_FREQUENCY, MIN_MOUNT_FREQUENCY

        if not MIN_MOUNT_FREQUENCY <= value <= MAX_MOUNT_FREQUENCY:
            raise ValueError(
                f"must lie between {MIN_MOUNT_FREQUENCY:g} Hz and {MAX_MOUNT_FREQUENCY:g} Hz (the range the "
                f"engine is tested over), got {value:.6g} Hz"
            )
        return value

    @model_validator(mode="after")
    def _damping(self) -> Product:
        if self.zeta is None and (self.zeta_vertical is None or self.zeta_horizontal is None):
            missing = "zeta_horizontal" if self.zeta_vertical is not None else "zeta_vertical"
            field = "zeta" if self.zeta_vertical is None and self.zeta_horizontal is None else missing
            raise ValueError(
                f"{field}: give the damping ratio, zeta (every axis) or zeta_vertical and zeta_horizontal"
            )
        return self

    @model_validator(mode="after")
    def _max_load(self) -> Product:
        if self.max_load is not None and self.max_load < self.rated_load.max:
            raise ValueError(
                f"max_load: must be at least rated_load.max ({self.rated_load.max:.6g} N), got "
                f"{self.max_load:.6g} N"
            )
        return self

    def pressure(self, load: float) -> float | None:
        """Gauge pressure ``load / effective_area`` at a load per isolator (N), Pa; None without an area."""
        return None if self.effective_area is None else float(load) / self.effective_area

    def label(self) -> str:
        """The product in words: ``id (maker series)``."""
        return f"{self.id} ({self.maker} {self.series})"


class Catalogue(CatalogueModel):
    """A list of isolator products, each with a unique ``id``."""

    name: str = Field("catalogue", max_length=200)
    description: str | None = Field(None, max_length=4000)
    currency: str = Field("EUR", max_length=16, description="the unit of every product's price")
    products: list[Product] = Field(min_length=1, max_length=MAX_PRODUCTS)

    @model_validator(mode="after")
    def _unique_ids(self) -> Catalogue:
        seen: dict[str, int] = {}
        for i, p in enumerate(self.products):
            if p.id in seen:
                raise ValueError(f"products[{i}].id: {p.id!r} repeats products[{seen[p.id]}]")
            seen[p.id] = i
        return self

    @property
    def ids(self) -> list[str]:
        return [p.id for p in self.products]

    def product(self, product_id: str, field: str = "model") -> Product:
        """The product called ``product_id``.

        Raises:
            UnknownProductError: naming ``field`` and the closest ids of the catalogue.
        """
        for p in self.products:
            if p.id == product_id:
                return p
        raise UnknownProductError(field, product_id, self)


class UnknownProductError(ValueError):
    """A ``model:`` naming no product of the catalogue; the message names the field and the closest ids."""

    def __init__(self, field: str, product_id: str, catalogue: Catalogue):
        close = difflib.get_close_matches(product_id, catalogue.ids, n=3, cutoff=0.4)
        hint = f"; closest: {', '.join(close)}" if close else f"; products: {', '.join(catalogue.ids[:10])}"
        super().__init__(f"{field}: no product {product_id!r} in catalogue {catalogue.name!r}{hint}")


def read_catalogue_file(path: str | Path) -> dict[str, Any]:
    """The mapping in a catalogue file (YAML, JSON, or CSV as :func:`catalogue_from_csv` reads it, named by
    the file's stem).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a mapping at the top level, or a CSV file that is not a table of products.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    kind: CatalogueFormat = "csv" if suffix == ".csv" else "json" if suffix == ".json" else "yaml"
    try:
        return read_catalogue_text(p.read_text(encoding="utf-8"), kind, p.stem)
    except ValueError as err:
        raise ValueError(f"{p}: {err}") from None


def read_catalogue_text(text: str, kind: CatalogueFormat = "yaml", name: str = "catalogue") -> dict[str, Any]:
    """The mapping a catalogue file's ``text`` holds, written as ``kind``; ``name`` names a CSV catalogue.

    Raises:
        ValueError: text that does not parse (with the line), or no mapping at the top level.
    """
    if kind == "csv":
        return catalogue_from_csv(text, name)
    import yaml

    try:
        data = json.loads(text) if kind == "json" else yaml.safe_load(text)
    except (ValueError, yaml.YAMLError) as err:
        raise ValueError(f"not {kind.upper()}: {' '.join(str(err).split())}") from None
    if not isinstance(data, Mapping):
        raise ValueError(f"expected a mapping at the top level, got {type(data).__name__}")
    return dict(data)


CSV_NESTED = {"rated_load": ("min", "max"), "footprint": ("x", "y")}
"""The two-part fields of a product and the column suffixes that give them in a CSV catalogue."""
_HEADER = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_.]*)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")
_BARE_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _csv_columns(header: list[str], line: int = 1) -> list[tuple[str, str | None]]:
    """Each header cell as (field, unit or None): ``rated_load.max [kN]`` -> (``rated_load.max``, ``kN``).

    Raises:
        ValueError: a cell that names no product field.
    """
    known = set(Product.model_fields) - set(CSV_NESTED)
    known |= {f"{k}.{part}" for k, parts in CSV_NESTED.items() for part in parts}
    columns = []
    for i, cell in enumerate(header, start=1):
        m = _HEADER.match(cell)
        if m is None or m.group(1) not in known:
            raise ValueError(
                f"line {line}, column {i}: {cell.strip()!r} is no product field (columns: id, type, maker, "
                "series, rated_load.min, rated_load.max, f_vertical, f_horizontal, zeta, ..., a unit in "
                "brackets after the name)"
            )
        columns.append((m.group(1), m.group(2) or None))
    if len({c for c, _ in columns}) != len(columns):
        raise ValueError(f"line {line}: a column is named twice")
    return columns


def catalogue_from_csv(text: str, name: str = "catalogue") -> dict[str, Any]:
    """A catalogue (as the mapping a YAML catalogue file holds) from a CSV table: a header row of product
    fields, each with an optional unit in brackets (``rated_load.max [kN]``, ``f_vertical [Hz]``), then
    one product per row. A bare number takes its column's unit; a cell may carry its own (``12 kN``); an
    empty cell leaves the field out. The two-part fields are two columns (``rated_load.min`` and
    ``rated_load.max``, ``footprint.x`` and ``footprint.y``). The unit of ``price`` is the currency
    (``price [EUR]``). Lines starting with ``#`` are comments.

    Raises:
        ValueError: no header or no product, an unknown column, or a row with more cells than the header,
            each naming its line.
    """
    import csv
    import io

    kept = [
        (n, line) for n, line in enumerate(text.splitlines(), start=1) if not line.lstrip().startswith("#")
    ]
    reader = csv.reader(io.StringIO("\n".join(line for _, line in kept)))
    numbered = []  # (line of the file, cells), blank rows left out
    try:
        for row in reader:
            if any(c.strip() for c in row):
                numbered.append((kept[reader.line_num - 1][0], row))
    except csv.Error as err:
        raise ValueError(f"not CSV: {err}") from None
    if not numbered:
        raise ValueError("no header row: the first line names the columns (id, type, maker, series, ...)")
    columns = _csv_columns(numbered[0][1], numbered[0][0])
    products: list[dict[str, Any]] = []
    for line, row in numbered[1:]:
        if len(row) > len(columns):
            raise ValueError(f"line {line}: {len(row)} cells under a header of {len(columns)}")
        product: dict[str, Any] = {}
        for (field, unit), raw in zip(columns, row, strict=False):
            cell = raw.strip()
            if not cell:
                continue
            value = f"{cell} {unit}" if unit and field != "price" and _BARE_NUMBER.match(cell) else cell
            head, _, part = field.partition(".")
            if part:
                product.setdefault(head, {})[part] = value
            else:
                product[field] = value
        if "footprint" in product:
            product["footprint"] = [product["footprint"].get("x"), product["footprint"].get("y")]
        products.append(product)
    if not products:
        raise ValueError("no product: one product a row under the header")
    catalogue: dict[str, Any] = {"name": name, "products": products}
    currency = dict(columns).get("price")
    if currency:
        catalogue["currency"] = currency
    return catalogue


def shipped_catalogue(name: str = DEFAULT_CATALOGUE) -> Catalogue:
    """The shipped catalogue ``name`` (:data:`SHIPPED_CATALOGUES`).

    Raises:
        KeyError: no shipped catalogue of that name.
    """
    return Catalogue.model_validate(read_catalogue_file(SHIPPED_CATALOGUES[name]))


def load_catalogue(source: str | Path | Mapping[str, Any] | Catalogue) -> Catalogue:
    """A validated catalogue from a shipped name, a file or data.

    Raises:
        pydantic.ValidationError: naming the field (``products.2.rated_load.max``).
        FileNotFoundError: a name that is neither a shipped catalogue nor a file.
    """
    if isinstance(source, Catalogue):
        return source
    if isinstance(source, Mapping):
        return Catalogue.model_validate(dict(source))
    if str(source) in SHIPPED_CATALOGUES:
        return shipped_catalogue(str(source))
    path = Path(source)
    if not path.is_file():
        raise FileNotFoundError(
            f"catalogue: no file {path} (shipped catalogues: {', '.join(SHIPPED_CATALOGUES)})"
        )
    return Catalogue.model_validate(read_catalogue_file(path))


def scene_catalogue(reference: str | Catalogue | None, field: str = "isolators.catalogue") -> Catalogue:
    """The catalogue a scene's ``catalogue:`` names: inline, a shipped name, or (none) the default.
    A file name is read only when a scene or study file is loaded (:func:`inline_catalogue_file`);
    validation itself never reads a user's file.

    Raises:
        ValueError: ``field`` naming no shipped catalogue.
    """
    if isinstance(reference, Catalogue):
        return reference
    name = DEFAULT_CATALOGUE if reference is None else reference
    if name not in SHIPPED_CATALOGUES:
        raise ValueError(
            f"{field}: {name!r} is not a shipped catalogue ({', '.join(SHIPPED_CATALOGUES)}); a catalogue "
            "file is read when a scene or study file is loaded (isolab simulate, run, size); over the API "
            "it is given inline"
        )
    return shipped_catalogue(name)


def product_figures(product: Product) -> dict[str, Any]:
    """What a mount naming ``product`` takes: its type as ``preset``, its ``f_vertical``, ``f_horizontal``
    (Hz) and ``zeta`` (1; without one, the vertical ratio), and ``zeta_vertical`` and ``zeta_horizontal``
    (1) where the product gives them."""
    figures: dict[str, Any] = {
        "preset": product.type,
        "f_vertical": product.f_vertical,
        "f_horizontal": product.f_horizontal,
        "zeta": product.zeta if product.zeta is not None else product.zeta_vertical,
    }
    for key in AXIS_DAMPING:
        if getattr(product, key) is not None:
            figures[key] = getattr(product, key)
    return figures


def inline_catalogue_file(scene: Any, here: str | Path) -> Any:
    """``scene`` (a scene definition as data) with an ``isolators.catalogue`` that names a file (relative to
    ``here``) replaced by the file's contents; anything else is returned as it is.

    Raises:
        FileNotFoundError: the named file does not exist.
    """
    if not isinstance(scene, Mapping):
        return scene
    iso = scene.get("isolators")
    ref = iso.get("catalogue") if isinstance(iso, Mapping) else None
    if not isinstance(ref, str) or ref in SHIPPED_CATALOGUES or not ref.lower().endswith(CATALOGUE_SUFFIXES):
        return scene
    path = Path(here) / ref
    if not path.is_file():
        raise FileNotFoundError(f"isolators.catalogue: no file {path}")
    assert isinstance(iso, Mapping)
    return {**scene, "isolators": {**iso, "catalogue": read_catalogue_file(path)}}
