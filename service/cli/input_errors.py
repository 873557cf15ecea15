"""How a command that reads a user's files reports what is wrong with them: one line a problem, each naming
the field and the reason, on stderr, and exit code 2 (the convention of every ``isolab`` command)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import typer


@contextmanager
def reported_input_errors(validation_prefix: str = "") -> Iterator[None]:
    """Turn a definition's problems (``DefinitionError``), a schema's (pydantic ``ValidationError``, each
    line led by ``validation_prefix``, e.g. ``"catalogue: "``), and an unreadable or wrong value
    (``OSError``, ``ValueError``) into ``error: <field>: <reason>`` lines and exit code 2."""
    from pydantic import ValidationError

    from isolab.studies.inputs.definitions import DefinitionError, dotted
    from isolab.studies.inputs.schema import error_messages

    try:
        yield
    except DefinitionError as err:
        for d in err.details:
            where = dotted([x for x in d["loc"] if x != "body"])
            typer.echo(f"error: {where}: {d['msg']}" if where != "body" else f"error: {d['msg']}", err=True)
        raise typer.Exit(code=2) from None
    except ValidationError as err:
        for line in error_messages(err):
            typer.echo(f"error: {validation_prefix}{line}", err=True)
        raise typer.Exit(code=2) from None
    except (OSError, ValueError) as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(code=2) from None
