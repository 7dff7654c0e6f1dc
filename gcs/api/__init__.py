"""The coordinator service's HTTP face: the FastAPI app over the engine (:mod:`gcs.service`).

:func:`gcs.api.app.create_app` builds it from :class:`gcs.api.settings.Settings`; ``python -m
gcs serve`` runs it with uvicorn. Every route is under ``/v1`` (and Prometheus ``/metrics``).
"""
