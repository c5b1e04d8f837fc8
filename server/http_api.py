"""HTTP API (FastAPI): health, Prometheus metrics, and the REST routes of the service."""
from __future__ import annotations

from fastapi import FastAPI, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from camdirector.server.session_router import SessionRouter


def build_app(router: SessionRouter, transports: dict[str, str]) -> FastAPI:
    app = FastAPI(title="camdirector", version="0.1.0",
                  description="Automated cinematographer: health, metrics, sessions, and offline jobs.")

    @app.get("/healthz")
    def healthz() -> dict:
        """Liveness and a short status: open sessions, worker processes, bound transports."""
        return {"status": "ok", "sessions": len(router.sessions), "workers": router.pool.size,
                "transports": transports}

    @app.get("/metrics")
    def metrics() -> Response:
        """Prometheus text exposition."""
        return Response(generate_latest(router.metrics.registry), media_type=CONTENT_TYPE_LATEST)

    @app.get("/v1/sessions")
    def sessions() -> dict:
        """Open sessions: worker, frames answered, streams attached, idle time."""
        return {"sessions": router.describe()}

    return app
