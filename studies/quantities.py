"""The quantities a user names: one value per case from a study dataset, by a short dotted name.

An objective, a constraint or a sensitivity output is written as the dataset variable's name followed by
labels that pick along its other dimensions, in any order: ``peak_point_displacement.tool.z`` (point
``tool``, axis ``z``), ``natural_frequency.1`` (mode 1), ``peak_isolator_force.z`` (axis ``z``; the
isolators not named are reduced). Dimensions left unnamed are reduced to the worst value: the largest,
except for variables whose name starts with ``min_`` (the smallest) and the criterion margins (the
smallest margin). ``settling_time.<point>`` is that point's settling time (``point_settling_time``); the
bare ``settling_time`` stays the whole base's.
"""

from __future__ import annotations

import xarray as xr

#: Variables that are not quantities of a case (labels, bookkeeping).
_NOT_QUANTITIES = frozenset({"status", "message"})

#: ``<alias>.<label>...`` -> the variable meant when labels follow the alias.
_LABELLED_ALIASES = {"settling_time": "point_settling_time"}


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


def _worst(name: str) -> str:
    return "min" if name.startswith("min_") or name == "criterion_margin" else "max"


def output_values(ds: xr.Dataset, spec: str) -> xr.DataArray:
    """One value per case of the quantity ``spec`` (see the module docstring), over the case dims.

    The result keeps the variable's ``units`` and ``long_name`` (the labels picked are added to the long
    name) and is named ``spec``.

    Raises:
        ValueError: an unknown variable or label, naming ``spec`` and the valid choices.
    """
    text = str(spec).strip()
    if not text:
        raise ValueError("the quantity is empty; name a variable, e.g. peak_point_displacement.tool.z")
    name, *labels = text.split(".")
    names = quantity_names(ds)
    if labels and name in _LABELLED_ALIASES and _LABELLED_ALIASES[name] in names:
        name = _LABELLED_ALIASES[name]
    if name not in names:
        raise ValueError(f"{spec!r}: no quantity {name!r}; choose one of: {', '.join(names)}")
    da = ds[name]
    own = [str(d) for d in da.dims if d not in case_dims(ds)]
    picked: list[str] = []
    for label in labels:
        for dim in own:
            values = [str(v) for v in da[dim].values] if dim in da.coords else []
            if label in values:
                da = da.isel({dim: values.index(label)}, drop=True)
                own.remove(dim)
                picked.append(f"{dim} {label}")
                break
        else:
            choices = "; ".join(
                f"{d}: {', '.join(str(v) for v in da[d].values)}" for d in own if d in da.coords
            )
            raise ValueError(
                f"{spec!r}: {label!r} labels none of {name}'s dimensions"
                + (f" ({choices})" if choices else f" ({name} has one value per case)")
            )
    attrs = dict(ds[name].attrs)
    if own:
        da = getattr(da, _worst(name))(dim=own, skipna=False)
        attrs["long_name"] = f"{attrs.get('long_name', name)} ({_worst(name)} over {', '.join(own)})"
    if picked:
        attrs["long_name"] = f"{attrs.get('long_name', name)}, {', '.join(picked)}"
    da = da.astype(float) if da.dtype.kind == "b" else da
    da.attrs = attrs
    return da.rename(text)
