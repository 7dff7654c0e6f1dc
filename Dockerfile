# The project image: the planner, the coordinator service (python -m gcs) and the stub
# simulator (python -m sitl_stub). docker-compose.yml runs it as migrate, api and sitl.
FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY planner ./planner
COPY gcs ./gcs
COPY sitl_stub ./sitl_stub
RUN pip wheel --no-cache-dir --no-deps --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    TCGCS_DATA_DIR=/data
COPY --from=build /wheels /tmp/wheels
RUN pip install --no-cache-dir /tmp/wheels/*.whl && rm -rf /tmp/wheels
RUN useradd --create-home --uid 10001 --user-group tcgcs \
    && mkdir -p /data /app \
    && chown tcgcs:tcgcs /data /app
WORKDIR /app
# Scenario files for sitl_stub --scenario and python -m gcs demo SCENARIO.
COPY --chown=tcgcs:tcgcs scenarios ./scenarios
USER tcgcs
VOLUME ["/data"]
# The service; the stub vehicles (SITL layout) on 5760, 5770, 5780.
EXPOSE 8600 5760 5770 5780
CMD ["python", "-m", "gcs", "serve", "--host", "0.0.0.0", "--port", "8600"]
