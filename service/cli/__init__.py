"""``isolab`` command-line interface (a Typer app, installed as the ``isolab`` console script).

Commands live as plain functions; each is registered on :data:`app` with ``app.command(name)(function)``
at the bottom of this module, so a new command is one import and one registration line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from isolab.service.settings import SettingsError, load_settings

app = typer.Typer(
    name="isolab",
    help="Batch design-of-experiments service for machines on vibration isolators.",
    no_args_is_help=True,
    add_completion=False,
)


def _print_version(value: bool) -> None:
    if value:
        from isolab.service.api.app import service_version

        typer.echo(f"isolab {service_version()}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_print_version, is_eager=True, help="Print the version and exit."),
    ] = False,
) -> None:
    """Batch design-of-experiments service for machines on vibration isolators."""


def serve(
    host: Annotated[str, typer.Option(help="Interface the HTTP server binds to.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="TCP port of the HTTP server.")] = 8000,
    workers: Annotated[
        int | None,
        typer.Option(min=1, help="Dask LocalCluster worker processes (env ISOLAB_WORKERS, default 2)."),
    ] = None,
    data: Annotated[
        Path | None,
        typer.Option(help="Study store directory (env ISOLAB_DATA_DIR, default ./data)."),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(help="Join this Dask scheduler instead of a LocalCluster (env DASK_SCHEDULER_ADDRESS)."),
    ] = None,
) -> None:
    """Run the HTTP API (one uvicorn process holding one Dask client)."""
    import uvicorn

    from isolab.service.api.app import create_app

    overrides = {"workers": workers, "data_dir": data, "scheduler_address": scheduler}
    try:
        settings = load_settings(**{key: value for key, value in overrides.items() if value is not None})
    except SettingsError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=2) from None
    from isolab.studies.results.store import StoreInUse, StoreLock

    # held for the process's life (the app's lifespan shares it): one service per data directory
    try:
        lock = StoreLock(settings.data_dir).acquire()
    except StoreInUse as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    try:
        uvicorn.run(create_app(settings), host=host, port=port, log_level="info")
    finally:
        lock.release()


app.command("serve")(serve)

from isolab.service.cli.local import run_study_command, simulate  # noqa: E402

app.command("simulate")(simulate)
app.command("run")(run_study_command)

from isolab.service.cli.remote import fetch_command, status_command, submit_command  # noqa: E402

app.command("submit")(submit_command)
app.command("status")(status_command)
app.command("fetch")(fetch_command)

from isolab.service.cli.calibration import calibrate_command  # noqa: E402

app.command("calibrate")(calibrate_command)

from isolab.service.cli.comparisons import compare_command  # noqa: E402

app.command("compare")(compare_command)

from isolab.service.cli.sizing import size_command  # noqa: E402

app.command("size")(size_command)

from isolab.service.cli.sensitivity import sensitivity_command  # noqa: E402

app.command("sensitivity")(sensitivity_command)

from isolab.service.cli.floor import floor_command  # noqa: E402

app.command("floor")(floor_command)
