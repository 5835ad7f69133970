"""The live station's web app: the page, a Server-Sent Events stream of the run, its frames, and control.

    GET  /                 the page (static files in vlnpilot/live/static)
    GET  /api/meta         the run's task and settings, the plan's bounds, state colours, keys, whether it controls,
                           where the scenario's events happen (issue 24)
    GET  /api/events       SSE: `step` (a line of episode.jsonl), `summary`, `status` (control), `end`
    GET  /frames/NAME      a frame of the run (front_NNN.jpg, rear_NNN.jpg)
    GET  /plan.png         the floor plan (scenes the simulator knows)
    POST /api/control      {"run", "action", "step", "movement", "state"}: 401 without the token when one is
                           set, 404 when the station only watches, 409 when it cannot act now
"""

from __future__ import annotations

import asyncio
import json
import re
from importlib import resources
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Header, HTTPException, Request
from fastapi.responses import FileResponse, JSONResponse, Response, StreamingResponse
from pydantic import BaseModel, Field

from vlnpilot.core.rundir import FRAMES
from vlnpilot.live.control import LiveControl, Refused
from vlnpilot.live.feed import RunFeed
from vlnpilot.live.guard import StationGuard, token_ok
from vlnpilot.live.plan import event_marks, plan_png, state_colors

POLL_S = 0.1  # how often a connection looks for new steps: well within the 1 s the page has to show one
FRAME_NAME = re.compile(r"^(front|rear)_\d{3,}\.jpg$")
STATIC = ("live.html", "live.css", "live.js")
KEYS = {"ArrowUp": "A1", "ArrowRight": "B1", "ArrowLeft": "C1", "q": "D1", "e": "D2", "ArrowDown": "E",
        "1": "A1", "2": "A2", "3": "A3", "4": "B1", "5": "B2", "6": "B3", "7": "C1", "8": "C2", "9": "C3",
        "0": "E"}


class ControlMessage(BaseModel):
    run: str = Field(max_length=300, description="the run this page shows: a message for another run is refused")
    action: str = Field(max_length=20)
    step: int | None = None
    movement: str | None = Field(default=None, max_length=8)
    state: str | None = Field(default=None, max_length=40)


def create_live_app(run_dir: Path, *, control: LiveControl | None = None, token: str | None = None,
                    scene: Any | None = None, host: str = "127.0.0.1") -> FastAPI:
    """The app for `run_dir`; with `control` the page can pause, stop and fly, else it only watches.

    `host` is the address it is served on: the guard (live/guard.py) answers only the Host names it stands for."""
    run_dir = Path(run_dir).resolve()
    run_id = run_dir.name
    plan, bounds = plan_png(scene) if scene is not None else (None, None)
    app = FastAPI(title="VLN-Pilot live station", docs_url=None, redoc_url=None, openapi_url=None)
    app.add_middleware(StationGuard, host=host, token=token)  # Host, Origin, token and body size, before the app

    @app.get("/", include_in_schema=False)
    def page() -> Response:
        return _static("live.html")

    @app.get("/static/{name}", include_in_schema=False)
    def static(name: str) -> Response:
        if name not in STATIC:
            raise HTTPException(404, "no such file")
        return _static(name)

    @app.get("/api/meta")
    def meta() -> dict[str, Any]:
        return {"run": run_id, "controls": control is not None, "token_required": token is not None,
                "plan": bounds, "state_colors": state_colors(), "keys": KEYS, "events": event_marks(scene)}

    @app.get("/frames/{name}")
    def frame(name: str) -> Response:
        path = run_dir / FRAMES / name
        if not FRAME_NAME.match(name) or not path.is_file():
            raise HTTPException(404, "no such frame")
        return FileResponse(path, media_type="image/jpeg", headers={"Cache-Control": "max-age=3600"})

    @app.get("/plan.png")
    def plan_image() -> Response:
        if plan is None:
            raise HTTPException(404, "this run's scene has no floor plan")
        return Response(plan, media_type="image/png")

    @app.get("/api/events")
    async def events(request: Request) -> StreamingResponse:
        return StreamingResponse(_stream(request, RunFeed(run_dir), control), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})

    @app.post("/api/control")
    def act(message: ControlMessage, authorization: str | None = Header(default=None)) -> JSONResponse:
        if token is not None and not token_ok(authorization, token):  # the guard checked it already: kept as a 2nd lock
            return JSONResponse({"error": "missing or wrong token (Authorization: Bearer ...)"}, status_code=401)
        if control is None:
            return JSONResponse({"error": "this station only watches the run"}, status_code=404)
        if message.run != run_id:
            return JSONResponse({"error": f"this station flies run {run_id}, not {message.run}"}, status_code=409)
        try:
            status = control.act(message.action, step=message.step, movement=message.movement, state=message.state)
        except Refused as exc:
            return JSONResponse({"error": str(exc)}, status_code=409)
        return JSONResponse(status)

    return app


def _static(name: str) -> Response:
    media = {"html": "text/html", "css": "text/css", "js": "text/javascript"}[name.rsplit(".", 1)[1]]
    text = resources.files("vlnpilot.live").joinpath("static", name).read_text(encoding="utf-8")
    return Response(text, media_type=f"{media}; charset=utf-8", headers={"Cache-Control": "no-store"})


def _event(kind: str, data: str) -> str:
    return f"event: {kind}\ndata: {data}\n\n"


async def _stream(request: Request, feed: RunFeed, control: LiveControl | None):
    """Every step so far, then each new one as it is written, the control status when it changes, and `end`."""
    version = -1
    while not await request.is_disconnected():
        for line in feed.new_lines():
            yield _event("step", line)
        if control is not None and control.version != version:
            status = control.status()
            version = status["version"]
            yield _event("status", json.dumps(status))
        summary = feed.changed_summary()
        if summary is not None:
            yield _event("summary", json.dumps(summary))
            if summary.get("status") != "running":
                for line in feed.new_lines():  # steps written just before the end
                    yield _event("step", line)
                yield _event("end", "{}")
                return
        await asyncio.sleep(POLL_S)
