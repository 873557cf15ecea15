# One image for the whole stack: the API (`isolab serve`), the Dask scheduler and the Dask workers.
# It holds the same install as `make serve` (the isolab package and its runtime dependencies).
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    ISOLAB_DATA_DIR=/data

RUN useradd --create-home --uid 1000 isolab \
    && mkdir -p /data \
    && chown isolab:isolab /data

WORKDIR /app
# The dependencies first, read from pyproject.toml alone: their layer is rebuilt only when pyproject.toml
# changes, so an edit of the source reinstalls isolab alone (seconds) instead of numba, dask and the rest.
# bokeh serves the Dask scheduler's dashboard (port 8787); distributed needs >= 3.1 for it.
COPY pyproject.toml /app/
RUN python -c "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']))" \
        > /tmp/requirements.txt \
    && pip install -r /tmp/requirements.txt 'bokeh>=3.1,<4' \
    && rm /tmp/requirements.txt
COPY . /app
RUN pip install --no-deps . && rm -rf /app/build
# The Dask scheduler and workers of docker-compose.yml run with the housekeeping and memory settings of the
# service's own cluster (isolab.studies.run.fanout.CLUSTER_HOUSEKEEPING), read from /etc/dask.
RUN mkdir -p /etc/dask \
    && python -c "import yaml; from isolab.studies.run.fanout import cluster_config_file; print(yaml.safe_dump(cluster_config_file()))" \
        > /etc/dask/isolab.yaml

USER isolab
WORKDIR /home/isolab
VOLUME ["/data"]
EXPOSE 8000

CMD ["isolab", "serve", "--host", "0.0.0.0", "--port", "8000", "--workers", "2", "--data", "/data"]
