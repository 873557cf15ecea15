"""``isolab submit``, ``isolab status`` and ``isolab fetch``: the commands that work on a running service,
through :class:`~isolab.service.client.Client`. Every failed request is one ``error: <message>`` line on
stderr and exit code 1."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, NoReturn, Self

import typer

from isolab.service.settings import DEFAULT_URL, URL_ENV

UrlOption = Annotated[str, typer.Option("--url", envvar=URL_ENV, help="Address of the isolab service.")]
"""``--url`` of a command that asks the service (``ISOLAB_URL`` when not given)."""
TokenOption = Annotated[
    str | None,
    typer.Option("--token", envvar="ISOLAB_API_TOKEN", help="Bearer token of the service, if any."),
]
"""``--token`` of a command that asks the service (``ISOLAB_API_TOKEN`` when not given)."""


class StudyProgressBar:
    """A rich progress bar of a study's cases, fed the statuses :meth:`Client.wait` polls:

    with StudyProgressBar(study_id) as bar:
        api.wait(study_id, progress=bar)
    """

    def __init__(self, study_id: str):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self._bar = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("cases"),
            TimeElapsedColumn(),
        )
        self._task = self._bar.add_task(study_id[:8], total=None)

    def __enter__(self) -> Self:
        self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.stop()

    def __call__(self, info: Mapping[str, Any]) -> None:
        """Show one polled status: the cases done of all, the study's name and status."""
        self._bar.update(
            self._task,
            total=info["progress"]["total"],
            completed=info["progress"]["done"],
            description=f"{info['name']} [{info['status']}]",
        )


def _fail(err: Exception) -> NoReturn:
    typer.echo(f"error: {err}", err=True)
    raise typer.Exit(code=1)


def _progress_text(info: Mapping[str, Any]) -> str:
    p = info["progress"]
    text = f"{info['id']}  {info['name']}  {info['status']}  {p['done']}/{p['total']} cases"
    if p.get("failed"):
        text += f" ({p['failed']} not ok)"
    if info.get("error"):
        text += f"  error: {info['error']}"
    return text


def submit_command(
    study: Annotated[Path, typer.Argument(help="Study file (YAML or JSON).", exists=True, dir_okay=False)],
    wait: Annotated[
        bool, typer.Option("--wait", help="Wait for the study to finish (progress bar).")
    ] = False,
    url: UrlOption = DEFAULT_URL,
    token: TokenOption = None,
) -> None:
    """Submit a study file to the service (its scene_file is read here and sent inline); print its id."""
    from isolab.service.client import Client, ClientError

    try:
        with Client(url, token=token) as api:
            accepted = api.submit(study)
            typer.echo(f"{accepted['id']}  queued  {accepted['n_cases']} cases")
            if not wait:
                return
            with StudyProgressBar(accepted["id"]) as bar:
                info = api.wait(accepted["id"], progress=bar)
    except (ClientError, OSError, ValueError) as err:
        _fail(err)
    typer.echo(_progress_text(info))
    if info["status"] != "done":
        raise typer.Exit(code=1)


def status_command(
    study_id: Annotated[
        str | None, typer.Argument(help="Study id; without it, list the latest studies.")
    ] = None,
    url: UrlOption = DEFAULT_URL,
    token: TokenOption = None,
    limit: Annotated[int, typer.Option(min=1, max=500, help="Studies to list.")] = 20,
) -> None:
    """Show one study's status and progress, or list the latest studies."""
    from isolab.service.client import Client, ClientError

    try:
        with Client(url, token=token) as api:
            if study_id is not None:
                info = api.status(study_id)
            else:
                rows = api.list(limit=limit)
    except ClientError as err:
        _fail(err)
    if study_id is not None:
        typer.echo(_progress_text(info))
        for key in ("created", "started", "finished"):
            if info.get(key):
                typer.echo(f"  {key:<9}{info[key]}")
        if info.get("parameters"):
            typer.echo(f"  varies   {', '.join(info['parameters'])}")
        return
    from rich.console import Console
    from rich.table import Table

    table = Table("id", "name", "status", "cases", "created")
    for r in rows:
        p = r["progress"]
        table.add_row(r["id"], r["name"], r["status"], f"{p['done']}/{p['total']}", r["created"][:19])
    Console(width=160).print(table)


def fetch_command(
    study_id: Annotated[str, typer.Argument(help="Study id.")],
    output: Annotated[
        Path, typer.Option("--output", "-o", help="Where to write the netCDF file.", dir_okay=False)
    ],
    url: UrlOption = DEFAULT_URL,
    token: TokenOption = None,
) -> None:
    """Download a done study's netCDF dataset."""
    from isolab.service.client import Client, ClientError

    try:
        with Client(url, token=token) as api:
            path = api.download(study_id, output)
    except (ClientError, OSError) as err:
        _fail(err)
    typer.echo(f"{path}  {path.stat().st_size} bytes")
