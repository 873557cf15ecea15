"""The quantities a user names: one value per case from a study dataset, by a short dotted name.

An objective, a constraint or a sensitivity output is written as the dataset variable's name followed by
labels that pick along its other dimensions, in any order: ``peak_point_displacement.tool.z`` (point
``tool``, axis ``z``), ``natural_frequency.1`` (mode 1), ``peak_isolator_force.z`` (axis ``z``; the
isolators not named are reduced). Dimensions left unnamed are reduced to the worst value as the output
catalogue judges it (:data:`isolab.engine.results.OUTPUTS`: the largest, but the smallest of the
smallest isolator load), the criterion margins to the smallest margin. ``settling_time.<point>`` is that
point's settling time (``point_settling_time``); the bare ``settling_time`` stays the whole base's, and
likewise ``ready_time.<point>`` (``point_ready_time``: the end of the last move plus that point's settling).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from isolab.engine.results import OUTPUTS

if TYPE_CHECKING:  # xarray loads where a dataset is read, not where a scene is
    import xarray as xr

#: Variables that are not quantities of a case (labels, bookkeeping).
_NOT_QUANTITIES = frozenset({"status", "message"})

#: ``<alias>.<label>...`` -> the variable meant when labels follow the alias.
_LABELLED_ALIASES = {"settling_time": "point_settling_time", "ready_time": "point_ready_time"}


def case_dims(ds: xr.Dataset) -> tuple[str, ...]:
    """The dimensions along which a dataset's cases lie (a grid's parameters, or ``case``)."""
    return tuple(str(d) for d in ds["status"].dims)


def quantity_names(ds: xr.Dataset) -> list[str]:
    """The variables of ``ds`` that hold one or more numbers per case, in dataset order."""
    dims = set(case_dims(ds))
    return [
        str(name)
        for name, var in ds.data_vars.items()
        if name not in _NOT_QUANTITIES and dims.issubset(var.dims) and var.dtype.kind in "fiub"
    ]


def worst_reduction(name: str) -> str:
    """How a dimension of the variable ``name`` left unnamed is reduced to the worst value: ``"max"`` or
    ``"min"``, as the output catalogue (:data:`isolab.engine.results.OUTPUTS`) judges it; the smallest
    criterion margin; the largest of anything else."""
    spec = OUTPUTS.get(name)
    if spec is not None:
        return spec.worst
    return "min" if name == "criterion_margin" else "max"


def pick_quantity(
    spec: str, names: Sequence[str], labels_of: Callable[[str], Mapping[str, Sequence[str] | None]]
) -> tuple[str, dict[str, str], list[str]]:
    """Read the quantity ``spec`` against what a dataset holds, without reading its values.

    Args:
        spec: the quantity's name (see the module docstring).
        names: the quantities there are, in dataset order (:func:`quantity_names`).
        labels_of: a variable's dimensions after the case dims -> their labels (None for a dimension
            without a coordinate), in the variable's order.

    Returns:
        (variable, dimension -> label picked in the order named, dimensions left to reduce).

    Raises:
        ValueError: an unknown variable or label, naming ``spec`` and the valid choices.
    """
    text = str(spec).strip()
    if not text:
        raise ValueError("the quantity is empty; name a variable, e.g. peak_point_displacement.tool.z")
    name, *labels = text.split(".")
    if labels and name in _LABELLED_ALIASES and _LABELLED_ALIASES[name] in names:
        name = _LABELLED_ALIASES[name]
    if name not in names:
        raise ValueError(f"{spec!r}: no quantity {name!r}; choose one of: {', '.join(names)}")
    dims = {
        str(d): None if values is None else [str(v) for v in values] for d, values in labels_of(name).items()
    }
    own = list(dims)
    picked: dict[str, str] = {}
    for label in labels:
        dim = next((d for d in own if label in (dims[d] or ())), None)
        if dim is None:
            choices = "; ".join(f"{d}: {', '.join(dims[d] or ())}" for d in own if dims[d] is not None)
            raise ValueError(
                f"{spec!r}: {label!r} labels none of {name}'s dimensions"
                + (f" ({choices})" if choices else f" ({name} has one value per case)")
            )
        picked[dim] = label
        own.remove(dim)
    return name, picked, own


def output_values(ds: xr.Dataset, spec: str) -> xr.DataArray:
    """One value per case of the quantity ``spec`` (see the module docstring), over the case dims.

    The result keeps the variable's ``units`` and ``long_name`` (the labels picked are added to the long
    name) and is named ``spec``.

    Raises:
        ValueError: an unknown variable or label, naming ``spec`` and the valid choices.
    """
    text = str(spec).strip()
    cases = set(case_dims(ds))

    def labels_of(name: str) -> dict[str, list[str] | None]:
        da = ds[name]
        return {
            str(d): [str(v) for v in da[d].values] if d in da.coords else None
            for d in da.dims
            if d not in cases
        }

    name, picked, own = pick_quantity(spec, quantity_names(ds), labels_of)
    labels = labels_of(name)
    da = ds[name]
    for dim, label in picked.items():
        da = da.isel({dim: (labels[dim] or []).index(label)}, drop=True)
    attrs = dict(ds[name].attrs)
    if own:
        worst = worst_reduction(name)
        da = getattr(da, worst)(dim=own, skipna=False)
        attrs["long_name"] = f"{attrs.get('long_name', name)} ({worst} over {', '.join(own)})"
    if picked:
        described = ", ".join(f"{dim} {label}" for dim, label in picked.items())
        attrs["long_name"] = f"{attrs.get('long_name', name)}, {described}"
    da = da.astype(float) if da.dtype.kind == "b" else da
    da.attrs = attrs
    return da.rename(text)
