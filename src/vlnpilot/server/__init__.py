"""The HTTP pilot server: `create_app()` (FastAPI) and `serve()` (uvicorn)."""

from vlnpilot.server.app import create_app, serve

__all__ = ["create_app", "serve"]
