"""Python client of the isolab REST API (on httpx).

    from isolab.service.client import Client

    with Client("http://127.0.0.1:8000") as api:
        study_id = api.submit("studies/examples/isolator-comparison.yaml")["id"]
        api.wait(study_id)                          # until done, failed or cancelled
        ds = api.dataset(study_id)                  # xarray.Dataset, in memory
        quiet = api.cases(study_id, filter="peak_displacement_y<5 mm,liftoff_any==false",
                          sort="settling_time")

A study file's ``scene_file`` is read here, on the client's machine, and sent inline (the server never
reads files). Every failed request raises :class:`ClientError` carrying the server's message.
"""

from __future__ import annotations

import builtins
import contextlib
import json
import os
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx

from isolab.service.settings import DEFAULT_URL, STATUS_WAIT_S, URL_ENV

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

KEEPALIVE_S = 2.0
"""Seconds an idle connection is kept for reuse (uvicorn closes idle connections after 5 s)."""
FINISHED = ("done", "failed", "cancelled")


class ClientError(RuntimeError):
    """A request failed. ``status_code`` is the HTTP status (None when the server was not reached),
    ``detail`` the server's error body (a message, or FastAPI's list of ``{loc, msg, type}``)."""

    def __init__(self, message: str, status_code: int | None = None, detail: Any = None):
        super().__init__(message)
        self.status_code = status_code
        self.detail = detail


def _message(response: httpx.Response) -> tuple[str, Any]:
    try:
        body = response.json()
    except ValueError:
        return response.text.strip() or response.reason_phrase, None
    detail = body.get("detail", body) if isinstance(body, dict) else body
    if isinstance(detail, list):
        parts = []
        for d in detail:
            if isinstance(d, Mapping):
                loc = ".".join(str(x) for x in d.get("loc", []) if x != "body")
                parts.append(f"{loc}: {d.get('msg', '')}" if loc else str(d.get("msg", "")))
            else:
                parts.append(str(d))
        return "; ".join(parts), detail
    return str(detail), detail


def read_study_file(path: str | Path) -> dict[str, Any]:
    """A study file (YAML or JSON) as a dict ready to send: its ``scene_file`` (relative to the study
    file) is read and inlined as ``scene``."""
    import yaml

    path = Path(path)
    text = path.read_text(encoding="utf-8")
    data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    data = dict(data)
    scene_file = data.pop("scene_file", None)
    if scene_file is not None:
        if data.get("scene") is not None:
            raise ValueError(f"{path}: scene_file: give scene or scene_file, not both")
        scene_path = path.resolve().parent / str(scene_file)
        if not scene_path.is_file():
            raise FileNotFoundError(f"{path}: scene_file: no file {scene_path}")
        scene_text = scene_path.read_text(encoding="utf-8")
        scene = json.loads(scene_text) if scene_path.suffix.lower() == ".json" else yaml.safe_load(scene_text)
        if not isinstance(scene, Mapping):
            raise ValueError(f"{scene_path}: expected a mapping at the top level, got {type(scene).__name__}")
        data["scene"] = dict(scene)
    return data


class Client:
    """The isolab REST API.

    Args:
        base_url: the service's address (default: ``ISOLAB_URL``, else ``http://127.0.0.1:8000``).
        token: bearer token, when the service has one (default: ``ISOLAB_API_TOKEN``).
        timeout: seconds to wait for one request (downloads: for each read).
    """

    def __init__(self, base_url: str | None = None, token: str | None = None, timeout: float = 60.0):
        token = token if token is not None else (os.environ.get("ISOLAB_API_TOKEN") or None)
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        base_url = base_url if base_url is not None else (os.environ.get(URL_ENV) or DEFAULT_URL)
        self.base_url = base_url.rstrip("/")
        self._http = httpx.Client(
            base_url=self.base_url,
            headers=headers,
            timeout=timeout,
            # idle connections are dropped before the server's 5 s keep-alive timeout closes them: a
            # request is never sent on a connection the server is closing at that moment
            limits=httpx.Limits(keepalive_expiry=KEEPALIVE_S),
        )

    # ------------------------------------------------------------------------------------ plumbing
    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _unreached(self, method: str, url: str, err: httpx.HTTPError) -> ClientError:
        """The error of a request that got no answer: one line; where no service listens, what to check."""
        if isinstance(err, httpx.ConnectError | httpx.ConnectTimeout):
            reason = str(err).partition("] ")[2] or str(err) or type(err).__name__
            return ClientError(
                f"cannot reach the isolab service at {self.base_url} ({reason.lower()}): is `isolab serve` "
                f"running at {self.base_url}? set {URL_ENV} or --url"
            )
        if isinstance(err, httpx.UnsupportedProtocol):
            return ClientError(
                f"{self.base_url!r} is not an http:// or https:// address: set {URL_ENV} or --url to the "
                f"service's address, such as {DEFAULT_URL}"
            )
        return ClientError(f"{method} {self.base_url}{url}: {type(err).__name__}: {err}")

    def _request(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        try:
            response = self._http.request(method, url, **kwargs)
        except httpx.HTTPError as err:
            raise self._unreached(method, url, err) from err
        if response.status_code >= 400:
            message, detail = _message(response)
            raise ClientError(
                f"{method} {url} -> {response.status_code}: {message}", response.status_code, detail
            )
        return response

    # ------------------------------------------------------------------------------------- studies
    def submit(self, study: Mapping[str, Any] | str | Path) -> dict[str, Any]:
        """Submit a study: a definition dict (inline scene), or the path of a YAML/JSON study file
        (its ``scene_file`` is read here and inlined). Returns ``{id, status, n_cases, links}``."""
        body = dict(study) if isinstance(study, Mapping) else read_study_file(study)
        return self._request("POST", "/studies", json=body).json()

    def status(self, study_id: str, wait: float = 0.0) -> dict[str, Any]:
        """A study's status, progress ``{done, total, failed}``, times, error and definition.

        Args:
            wait: seconds the service may hold the answer while the study is queued or running (at most
                its bound, 30 s): it answers as soon as the study ends, else at ``wait`` with the
                progress then."""
        params = {"wait": f"{wait:g}"} if wait > 0 else None
        return self._request("GET", f"/studies/{study_id}", params=params).json()

    def list(self, **filters: Any) -> builtins.list[dict[str, Any]]:
        """Studies in the catalog, newest first. Filters: name, status, isolator_type, created_after,
        created_before (ISO 8601), limit (<= 500), offset."""
        params = {k: v for k, v in filters.items() if v is not None}
        return self._request("GET", "/studies", params=params).json()["items"]

    def wait(
        self,
        study_id: str,
        progress: Callable[[dict[str, Any]], object] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """Wait until the study is done, failed or cancelled; returns its final status.

        Each status request waits on the service for the study to end (``GET /studies/{id}?wait=``), so
        the end is seen as soon as it comes, and the progress every ``poll`` seconds meanwhile.

        Args:
            progress: called with each status asked (its ``progress`` is ``{done, total, failed}``),
                e.g. the progress bar of ``isolab submit --wait``,
                :class:`isolab.service.cli.remote.StudyProgressBar`.
            poll: seconds between progress reports.
            timeout: give up after this many seconds (ClientError); None waits for ever.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        read_timeout = self._http.timeout.read
        step = min(max(float(poll), 0.0), STATUS_WAIT_S, read_timeout / 2 if read_timeout else STATUS_WAIT_S)
        while True:
            asked = time.monotonic()
            hold = step if deadline is None else min(step, max(deadline - asked, 0.0))
            info = self.status(study_id, wait=hold)
            if progress is not None:
                progress(info)
            if info["status"] in FINISHED:
                return info
            if deadline is not None and time.monotonic() > deadline:
                raise ClientError(f"study {study_id} is still {info['status']} after {timeout} s")
            time.sleep(max(step - (time.monotonic() - asked), 0.0))  # a service that answered at once

    def download(self, study_id: str, path: str | Path) -> Path:
        """Stream a done study's netCDF dataset to ``path`` (written atomically); returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as out:
                try:
                    with self._http.stream("GET", f"/studies/{study_id}/dataset") as response:
                        if response.status_code >= 400:
                            response.read()
                            message, detail = _message(response)
                            raise ClientError(
                                f"GET /studies/{study_id}/dataset -> {response.status_code}: {message}",
                                response.status_code,
                                detail,
                            )
                        for chunk in response.iter_bytes():
                            out.write(chunk)
                except httpx.HTTPError as err:
                    raise self._unreached("GET", f"/studies/{study_id}/dataset", err) from err
            from isolab.studies.results.store import new_file_mode

            os.chmod(tmp_name, new_file_mode())  # as a file opened for writing would be, not mkstemp's 0600
            os.replace(tmp_name, path)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise
        return path

    def dataset(self, study_id: str) -> xr.Dataset:
        """A done study's dataset, loaded into memory (downloaded to a temporary file, opened, loaded,
        closed, removed)."""
        import xarray as xr

        with tempfile.TemporaryDirectory(prefix="isolab-") as tmp:
            path = self.download(study_id, Path(tmp) / f"{study_id}.nc")
            with xr.open_dataset(path) as ds:
                return ds.load()

    def cases(self, study_id: str, **query: Any) -> builtins.list[dict[str, Any]]:
        """Rows of a done study's case table: one dict per case. Query: filter, sort, columns (a list or a
        comma-separated string), limit, offset."""
        params = {
            k: (",".join(v) if isinstance(v, list | tuple) else v) for k, v in query.items() if v is not None
        }
        params["format"] = "json"
        return self._request("GET", f"/studies/{study_id}/cases", params=params).json()["rows"]

    def timeseries(self, study_id: str, case: int, every: int = 1) -> dict[str, Any]:
        """Time histories of one case (recomputed by the server), SI units."""
        return self._request(
            "GET", f"/studies/{study_id}/cases/{case}/timeseries", params={"every": every}
        ).json()

    def delete(self, study_id: str) -> None:
        """Cancel a queued or running study; remove a finished one."""
        self._request("DELETE", f"/studies/{study_id}")

    # ---------------------------------------------------------------------------------- sensitivity
    def sensitivity_answer(self, study_id: str, output: str) -> dict[str, Any]:
        """The sensitivity of ``output`` of a done study as the service answers it (JSON)."""
        return self._request("GET", f"/studies/{study_id}/sensitivity", params={"output": output}).json()

    def sensitivity(self, study_id: str, output: str) -> pd.DataFrame:
        """Sensitivity indices of ``output`` (e.g. ``peak_point_displacement.tool.z``) of a done study: one
        row per parameter (index: its name), a column per index (``S1``, ``ST`` or ``delta``, ``S1``) and
        one per confidence half-width (``S1_conf``...), plus ``long_name`` and ``unit`` of the parameter.
        ``df.attrs`` holds the method, its description, the output, its unit and the case counts."""
        return sensitivity_frame(self.sensitivity_answer(study_id, output))

    def sensitivity_png(self, study_id: str, output: str) -> bytes:
        """The bar chart of :meth:`sensitivity` as PNG bytes."""
        return self._request("GET", f"/studies/{study_id}/sensitivity.png", params={"output": output}).content

    # ---------------------------------------------------------------------------------- comparisons
    def compare(
        self,
        scene: Mapping[str, Any] | str | Path,
        types: builtins.list[str] | None = None,
        simulation: Mapping[str, Any] | None = None,
        cost_order: builtins.list[str] | None = None,
        tune: bool = False,
        samples: int | None = None,
        require: float | None = None,
        seed: int | None = None,
    ) -> Any:
        """Run one scene (a dict, or a YAML/JSON scene file) under several isolator types (default all
        three); the side-by-side table as a pandas DataFrame: one row per isolator type, one column per
        output (SI) and, when the scene has design criteria, ``meets_criteria`` and ``margin_<criterion>``
        (fraction of the limit to spare, positive: met).

        ``df.attrs`` holds ``recommendation`` (``isolator_type``: the cheapest type in ``cost_order``,
        default elastomer < air < active, that meets every criterion; ``reason``), ``requirements`` (the
        criteria: name, limit, unit), ``units`` (column -> SI unit), ``best`` (column -> best type) and
        ``simulation``; with ``tune`` (each type first tuned to the criteria within its physical range),
        also ``tuning`` (type -> values found). With a ``tolerances:`` block in the scene, each type is also
        judged on ``samples`` machines drawn from it (seed ``seed``; the service's defaults when None):
        ``robustness`` gives the probability of meeting every criterion, and the recommendation is the
        most probable type that reaches ``require`` (a probability, 0 to 1). The products of a catalogue
        are compared by :meth:`compare_products`."""
        body: dict[str, Any] = {"scene": scene_data(scene)}
        if types is not None:
            body["isolator_types"] = list(types)
        if simulation is not None:
            body["simulation"] = dict(simulation)
        if cost_order is not None:
            body["cost_order"] = list(cost_order)
        if tune:
            body["tune"] = True
        for key, value in (("samples", samples), ("require", require), ("seed", seed)):
            if value is not None:
                body[key] = value
        from isolab.studies.answers.comparisons import comparison_frame

        return comparison_frame(self._request("POST", "/comparisons", json=body).json())

    def compare_products(
        self,
        scene: Mapping[str, Any] | str | Path,
        catalogue: Mapping[str, Any] | str | Path,
        *,
        types: builtins.list[str] | None = None,
        simulation: Mapping[str, Any] | None = None,
        margin: float | None = None,
        per_corner: builtins.list[int] | None = None,
        samples: int | None = None,
        require: float | None = None,
        seed: int | None = None,
    ) -> dict[str, Any]:
        """Run one scene (a dict, or a YAML/JSON scene file) on each product of ``catalogue`` that carries
        its static loads (``POST /comparisons`` with a catalogue): the service's answer, a dict. Read it as
        a table with :func:`product_frame`.

        ``catalogue`` is a catalogue file (YAML, JSON or CSV: read here, sent inline), the catalogue as a
        mapping (as in a catalogue file), or a shipped catalogue's name (``representative``). ``types``
        picks the products' types (default all); ``margin`` (1) is how far each isolator's static load may
        change either way and stay in its rated range (the service's default 0.10 when None);
        ``per_corner`` the numbers of isolators side by side a mount position may take (default the
        scene's, else 1). With a ``tolerances:`` block in the scene, ``samples``, ``require`` and ``seed``
        as in :meth:`compare`.

        The answer's ``recommendation.product`` is the cheapest priced product that meets every
        criterion, ``catalogue.products`` every product's counts, load margins, pressures, cost, and the
        reason a skipped one does not fit.

        Raises:
            FileNotFoundError: ``catalogue`` names a file (ends in .yaml, .yml, .json or .csv) that is not
                there.
            ValueError: a catalogue file that does not parse.
            ClientError: the service refused the request (a 422 naming the field, such as
                ``catalogue.products.2.rated_load.max``).
        """
        body: dict[str, Any] = {"scene": scene_data(scene), "catalogue": catalogue_data(catalogue)}
        for key, value in (
            ("isolator_types", None if types is None else list(types)),
            ("simulation", None if simulation is None else dict(simulation)),
            ("margin", None if margin is None else float(margin)),
            ("per_corner", None if per_corner is None else [int(n) for n in per_corner]),
            ("samples", samples),
            ("require", require),
            ("seed", seed),
        ):
            if value is not None:
                body[key] = value
        return self._request("POST", "/comparisons", json=body).json()

    def simulate(
        self,
        scene: Mapping[str, Any],
        simulation: Mapping[str, Any] | None = None,
        max_points: int = 2000,
    ) -> dict[str, Any]:
        """Run one scene now on the service (``POST /simulations``): its ``summary`` (column -> value in
        SI, unit, long name), ``modes``, ``isolators`` and ``traces`` (at most ``max_points`` samples a
        trace)."""
        body: dict[str, Any] = {"scene": dict(scene), "max_points": int(max_points)}
        if simulation is not None:
            body["simulation"] = dict(simulation)
        return self._request("POST", "/simulations", json=body).json()

    # --------------------------------------------------------------------------------- calibrations
    def calibrate(
        self,
        scene: Mapping[str, Any] | str | Path,
        measurement: Mapping[str, Any] | str | Path,
        fit: builtins.list[str | Mapping[str, Any]],
        offset: Mapping[str, Any] | None = None,
        simulation: Mapping[str, Any] | None = None,
        highpass: float | str | None = None,
        lowpass: float | str | None = None,
        plot: bool = False,
        noise: Mapping[str, float | str] | None = None,
        starts: int | None = None,
        progress: Callable[[dict[str, Any]], object] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """Fit ``fit``'s parameters of ``scene`` (a dict, or a YAML/JSON scene file) to ``measurement``: a
        CSV or netCDF file (read here: CSV is sent as text, netCDF as columns), or the request's form
        (``{"csv": text}`` or ``{"time", "channels"}``). ``fit``: ``"isolators.f_vertical=1:6"`` strings or
        ``{"path", "lower", "upper"}`` dicts. Submits the calibration job (:meth:`calibration_submit`) and
        waits for it (:meth:`calibration_wait`: ``progress``, ``poll``, ``timeout`` in s, None for ever;
        on a timeout the job is cancelled). Answers fitted values +- 1 sigma (SI), the misfit per channel
        before and after and the calibrated scene (``scene_yaml``); ``plot=True`` adds a base64 PNG.
        ``noise``: channel -> a sensor's noise (one sample's standard deviation, SI or ``"0.01 mm"``), what
        the goodness of fit is judged against; ``starts``: fits from the scene's values and Sobol' points
        (1 to 16), the best kept.
        A refused request or a failed fit raises :class:`ClientError`."""
        from isolab.studies.answers.calibration import parse_fit, read_measurement

        if not isinstance(scene, Mapping):
            import yaml

            path = Path(scene)
            text = path.read_text(encoding="utf-8")
            scene = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
        if isinstance(measurement, Mapping):
            meas: dict[str, Any] = dict(measurement)
        elif Path(measurement).suffix.lower() in (".nc", ".nc4", ".cdf", ".netcdf"):
            m = read_measurement(measurement)
            meas = {
                "time": m.time.tolist(),
                "channels": [{"name": c.name, "unit": "", "values": c.values.tolist()} for c in m.channels],
            }
        else:
            meas = {"csv": Path(measurement).read_text(encoding="utf-8")}
        specs = []
        for f in fit:
            if isinstance(f, str):
                s = parse_fit(f)
                specs.append({"path": s.path, "lower": s.lower, "upper": s.upper, "start": s.start})
            else:
                specs.append(dict(f))
        body: dict[str, Any] = {
            "scene": dict(scene),  # type: ignore[arg-type]  # a mapping by now
            "measurement": meas,
            "fit": [{k: v for k, v in s.items() if v is not None} for s in specs],
            "plot": plot,
        }
        for key, value in (("offset", offset), ("simulation", simulation)):
            if value is not None:
                body[key] = dict(value)
        for key, corner in (("highpass", highpass), ("lowpass", lowpass)):
            if corner is not None:
                body[key] = corner
        if noise is not None:
            body["noise"] = dict(noise)
        if starts is not None:
            body["starts"] = int(starts)
        job = self.calibration_submit(body)
        try:
            done = self.calibration_wait(job["id"], progress=progress, poll=poll, timeout=timeout)
        except BaseException:  # a timeout, or the caller interrupted: the fit stops on the service too
            with contextlib.suppress(ClientError):
                self.calibration_cancel(job["id"])
            raise
        if done["status"] != "done":
            raise ClientError(f"calibration {job['id']} failed: {done.get('error')}", None, done)
        return done["result"]

    def calibration_submit(self, body: Mapping[str, Any]) -> dict[str, Any]:
        """Submit a calibration request body (``POST /calibrations``); its job: ``{id, status, estimate,
        progress}``."""
        return self._request("POST", "/calibrations", json=dict(body)).json()

    def calibration_status(self, calibration_id: str) -> dict[str, Any]:
        """A calibration job: ``status``, ``estimate``, ``progress``, ``error`` and, once done, ``result``."""
        return self._request("GET", f"/calibrations/{calibration_id}").json()

    def calibration_wait(
        self,
        calibration_id: str,
        progress: Callable[[dict[str, Any]], object] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """Poll until the calibration is done or failed; its final job (see :meth:`calibration_status`).
        ``timeout``: give up after this many seconds (ClientError); None waits for ever."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            info = self.calibration_status(calibration_id)
            if progress is not None:
                progress(info)
            if info["status"] in ("done", "failed"):
                return info
            if deadline is not None and time.monotonic() > deadline:
                raise ClientError(f"calibration {calibration_id} is still {info['status']} after {timeout} s")
            time.sleep(poll)

    def calibration_cancel(self, calibration_id: str) -> None:
        """Stop a calibration and remove it (``DELETE /calibrations/{id}``)."""
        self._request("DELETE", f"/calibrations/{calibration_id}")


def scene_data(scene: Mapping[str, Any] | str | Path) -> dict[str, Any]:
    """A scene to send: the mapping itself, or the contents of a YAML or JSON scene file.

    Raises:
        FileNotFoundError: no such file.
        ValueError: a file that holds no mapping.
    """
    if isinstance(scene, Mapping):
        return dict(scene)
    import yaml

    path = Path(scene)
    text = path.read_text(encoding="utf-8")
    data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return dict(data)


def catalogue_data(catalogue: Mapping[str, Any] | str | Path) -> dict[str, Any] | str:
    """A catalogue to send: a mapping as it is, a catalogue file's contents (YAML, JSON or CSV, read on this
    machine), or a shipped catalogue's name as it is.

    Raises:
        FileNotFoundError: a name ending in a catalogue file's suffix (.yaml, .yml, .json, .csv) that names
            no file.
        ValueError: a file that does not parse.
    """
    from isolab.studies.inputs.catalogues import CATALOGUE_SUFFIXES, read_catalogue_file

    if isinstance(catalogue, Mapping):
        return dict(catalogue)
    path = Path(catalogue)
    if path.is_file():
        return read_catalogue_file(path)
    if isinstance(catalogue, Path) or str(catalogue).lower().endswith(CATALOGUE_SUFFIXES):
        raise FileNotFoundError(f"catalogue: no file {path}")
    return str(catalogue)


def product_frame(answer: Mapping[str, Any]) -> pd.DataFrame:
    """A catalogue comparison's answer (:meth:`Client.compare_products`) as a DataFrame: one row per product
    (index ``product``, cheapest first), with ``count``, ``unit_price`` and ``cost`` (``attrs["currency"]``),
    ``feasible`` and ``why_not`` in words, ``pressure_min``/``pressure_max`` (Pa), ``load_margin`` (1),
    ``peak_deflection`` and ``stroke`` (m), ``stroke_used`` (1), ``criteria_met`` and ``recommended``
    (:func:`isolab.studies.answers.product_comparison.product_frame`; units in ``attrs["units"]``)."""
    from isolab.studies.answers.product_comparison import product_frame as frame

    return frame(dict(answer))


def sensitivity_frame(answer: Mapping[str, Any]) -> pd.DataFrame:
    """A sensitivity answer (JSON of ``/studies/{id}/sensitivity``) as a DataFrame (see
    :meth:`Client.sensitivity`); missing indices are NaN."""
    import pandas as pd

    columns: dict[str, Any] = {}
    for kind, values in answer["indices"].items():
        columns[kind] = [float("nan") if v is None else v for v in values]
        conf = answer["conf"].get(kind, [None] * len(values))
        columns[f"{kind}_conf"] = [float("nan") if v is None else v for v in conf]
    columns["long_name"] = list(answer["parameter_long_names"])
    columns["unit"] = list(answer["parameter_units"])
    df = pd.DataFrame(columns, index=pd.Index(list(answer["parameters"]), name="parameter"))
    keys = ("method", "method_name", "design", "output", "long_name", "unit", "n_cases", "n_total")
    df.attrs.update({k: answer[k] for k in keys})
    df.attrs.update(
        n_excluded=answer["n_excluded"], n_dropped=answer.get("n_dropped", 0), notes=list(answer["notes"])
    )
    return df
