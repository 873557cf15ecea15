"""``isolab sensitivity``: which varied parameters drive an output of a study, from the service (a study
id) or from a dataset file on this machine (``isolab run``'s netCDF)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from isolab.service.cli.remote import TokenOption, UrlOption
from isolab.service.settings import DEFAULT_URL


def _local_answer(path: Path, output: str) -> dict[str, Any]:
    import xarray as xr

    from isolab.studies.answers.sensitivity import sensitivity

    with xr.open_dataset(path) as ds:
        return sensitivity(ds.load(), output).to_dict()


def _shown(value: float | None, digits: int = 3) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def sensitivity_command(
    study: Annotated[str, typer.Argument(help="Study id on the service, or a study's netCDF file.")],
    output: Annotated[
        str,
        typer.Option(
            "--output",
            help="The output, dotted: peak_point_displacement.tool.z, settling_time, natural_frequency.1...",
        ),
    ],
    plot: Annotated[
        Path | None, typer.Option(help="Write the bar chart of the indices to this PNG.", dir_okay=False)
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the answer as JSON.")] = False,
    url: UrlOption = DEFAULT_URL,
    token: TokenOption = None,
) -> None:
    """Sensitivity indices of one output: Sobol' S1 and ST for a saltelli design, Borgonovo's delta and S1
    for other samples and grids, each with its 95 % confidence interval, parameters ranked."""
    from isolab.service.client import Client, ClientError

    local = Path(study)
    try:
        if local.suffix == ".nc" or local.is_file():
            answer = _local_answer(local, output)
            png = None
            if plot is not None:
                from isolab.service.plots.sensitivity import sensitivity_png

                png = sensitivity_png(answer, local.stem)
        else:
            with Client(url, token=token) as api:
                answer = api.sensitivity_answer(study, output)
                png = api.sensitivity_png(study, output) if plot is not None else None
    except (ClientError, OSError, ValueError) as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(code=2) from None
    if plot is not None and png is not None:
        plot.write_bytes(png)
    if as_json:
        typer.echo(json.dumps(answer, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    kinds = list(answer["indices"])
    rank_by = "ST" if "ST" in kinds else "delta"
    values = answer["indices"][rank_by]
    order = sorted(range(len(values)), key=lambda i: -(values[i] if values[i] is not None else -math.inf))
    console = Console(width=140)
    unit = f" ({answer['unit']})" if answer["unit"] else ""
    console.print(
        f"[bold]{answer['output']}[/bold]: {answer['long_name']}{unit}\n{answer['method_name']}; "
        f"{answer['n_cases']} of {answer['n_total']} cases used; ranked by {rank_by}"
    )
    table = Table("rank", "parameter", "unit", *[f"{k} ± 95 %" for k in kinds])
    for rank, i in enumerate(order, start=1):
        cells = [
            f"{_shown(answer['indices'][k][i])} ± {_shown(answer['conf'][k][i])}".replace("- ± -", "-")
            for k in kinds
        ]
        table.add_row(str(rank), answer["parameters"][i], answer["parameter_units"][i], *cells)
    console.print(table)
    for note in answer["notes"]:
        console.print(f"note: {note}")
    if plot is not None:
        console.print(f"plot -> {plot}")
