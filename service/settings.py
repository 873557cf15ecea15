"""Runtime settings of the isolab service, read from environment variables.

Every setting has an environment variable and a default:

=========================  ==================  ===========================================
variable                   default             meaning
=========================  ==================  ===========================================
ISOLAB_DATA_DIR            ./data              directory holding the study store and catalog
DASK_SCHEDULER_ADDRESS     (unset)             Dask scheduler to join; unset -> LocalCluster
ISOLAB_WORKERS             2                   LocalCluster worker processes (1 thread each)
ISOLAB_API_TOKEN           (unset)             bearer token required by the API; unset -> open
ISOLAB_MAX_CASES           1000000             largest number of cases one study may hold
ISOLAB_MAX_BODY_BYTES      10485760 (10 MiB)   largest accepted request body, in bytes
ISOLAB_CORS_ORIGINS        (empty)             comma-separated allowed origins; empty -> none
ISOLAB_DASHBOARD_PORT      (unset)             Dask dashboard on 127.0.0.1:PORT; unset -> off
=========================  ==================  ===========================================

An empty variable counts as unset. A bad value raises :class:`SettingsError` naming the variable.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

DEFAULT_URL = "http://127.0.0.1:8000"
"""Where ``isolab serve`` listens by default; ``ISOLAB_URL`` (or the commands' ``--url``) names another."""
URL_ENV = "ISOLAB_URL"
"""The environment variable the command line and the Python client read the service's address from."""
STATUS_WAIT_S = 30.0
"""Longest the service holds a status request for its study to end (``GET /studies/{id}?wait=``), s: the
route's bound and the client's step."""

MIB = 1024 * 1024

#: Environment variable read for each :class:`Settings` field.
ENV_VARS: dict[str, str] = {
    "data_dir": "ISOLAB_DATA_DIR",
    "scheduler_address": "DASK_SCHEDULER_ADDRESS",
    "workers": "ISOLAB_WORKERS",
    "api_token": "ISOLAB_API_TOKEN",
    "max_cases": "ISOLAB_MAX_CASES",
    "max_body_bytes": "ISOLAB_MAX_BODY_BYTES",
    "cors_origins": "ISOLAB_CORS_ORIGINS",
    "dashboard_port": "ISOLAB_DASHBOARD_PORT",
}


class SettingsError(ValueError):
    """A setting has a value the service cannot run with."""


@dataclass(frozen=True)
class Settings:
    """Service settings; build them with :func:`load_settings`.

    Attributes:
        data_dir: directory of the study store (netCDF files and catalog).
        scheduler_address: address of an external Dask scheduler (e.g. ``tcp://scheduler:8786``);
            ``None`` starts a LocalCluster inside the service.
        workers: number of LocalCluster worker processes, one thread each (ignored with a scheduler).
        api_token: bearer token the API requires; ``None`` leaves the API open.
        max_cases: largest number of cases accepted in one study.
        max_body_bytes: largest accepted request body, in bytes.
        cors_origins: origins allowed by CORS; empty means no cross-origin access.
        dashboard_port: TCP port of the Dask dashboard of the in-process LocalCluster, served on the
            loopback interface (``127.0.0.1``) alone; ``None`` (the default) serves no dashboard.
    """

    data_dir: Path = Path("./data")
    scheduler_address: str | None = None
    workers: int = 2
    api_token: str | None = None
    max_cases: int = 1_000_000
    max_body_bytes: int = 10 * MIB
    cors_origins: tuple[str, ...] = field(default_factory=tuple)
    dashboard_port: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.data_dir, Path):
            object.__setattr__(self, "data_dir", Path(self.data_dir))
        if str(self.data_dir).strip() == "":
            raise SettingsError(
                f"{ENV_VARS['data_dir']} (data_dir) must be a directory path, got an empty value"
            )
        for name in ("scheduler_address", "api_token"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, str) or value.strip() == ""):
                raise SettingsError(
                    f"{ENV_VARS[name]} ({name}) must be a non-empty string or unset, got {value!r}"
                )
        for name in ("workers", "max_cases", "max_body_bytes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise SettingsError(f"{ENV_VARS[name]} ({name}) must be an integer >= 1, got {value!r}")
        if isinstance(self.cors_origins, str):
            object.__setattr__(self, "cors_origins", _split_origins(self.cors_origins))
        else:
            object.__setattr__(self, "cors_origins", tuple(self.cors_origins))
        for origin in self.cors_origins:
            if origin != "*" and not origin.startswith(("http://", "https://")):
                raise SettingsError(
                    f"{ENV_VARS['cors_origins']} (cors_origins) entries must be '*' or start with "
                    f"http:// or https://, got {origin!r}"
                )
        port = self.dashboard_port
        if port is not None and (isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536):
            raise SettingsError(
                f"{ENV_VARS['dashboard_port']} (dashboard_port) must be a TCP port 1 to 65535 or unset, "
                f"got {port!r}"
            )


def _split_origins(raw: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in raw.split(",") if part.strip())


def _parse_int(variable: str, raw: str) -> int:
    try:
        return int(raw.strip())
    except ValueError:
        raise SettingsError(f"{variable} must be an integer, got {raw!r}") from None


def _from_environ(environ: Mapping[str, str]) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for name, variable in ENV_VARS.items():
        raw = environ.get(variable, "")
        if raw.strip() == "":
            continue
        if name in ("workers", "max_cases", "max_body_bytes", "dashboard_port"):
            values[name] = _parse_int(variable, raw)
        elif name == "data_dir":
            values[name] = Path(raw.strip())
        elif name == "cors_origins":
            values[name] = _split_origins(raw)
        else:
            values[name] = raw.strip()
    return values


def load_settings(**overrides: Any) -> Settings:
    """Read settings from the environment, then apply keyword overrides.

    Args:
        **overrides: field values of :class:`Settings` that win over the environment
            (e.g. ``workers=4`` from a command-line flag).

    Raises:
        SettingsError: an environment variable or override has an invalid value.
        TypeError: an override names no field of :class:`Settings`.
    """
    known = {f.name for f in fields(Settings)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise TypeError(
            f"unknown setting(s) {', '.join(unknown)}; known settings are {', '.join(sorted(known))}"
        )
    return replace(Settings(**_from_environ(os.environ)), **overrides)
