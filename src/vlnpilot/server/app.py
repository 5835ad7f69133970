"""The pilot server (the paper's "VLLM Server", FastAPI instead of Flask): one decision per HTTP request.

`POST /v1/decide` takes the paper's five inputs (image as base64 JPEG/PNG, query, topological map,
state, previous movement) plus the FSM profile and controller feedback, asks a pilot, and returns
its Decision. A client with conversation memory (the `remote` pilot's `history` option) sends its earlier turns
with each request (`history`): the server is stateless, and its pilots never remember one client for another.
`GET /healthz` says the server is up; the OpenAPI docs are at /docs.

Errors are JSON (`ErrorBody`), never a traceback: 401 bad/missing bearer token, 403 a pilot this server
does not serve (the body lists the allowed SPECs), 413 body too large, 415 not JSON, 422 bad field or image,
502 the provider failed or its reply was unusable, 503 the provider is unavailable or rate limiting.
`reason` and `fatal` carry the pilot's own PilotError fields, so the `remote` pilot can raise the same error
on the client side.
"""

from __future__ import annotations

import base64
import contextlib
import hmac
import io
import ipaddress
import logging
import os
from collections.abc import AsyncIterator, Callable, Collection, Iterator
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from fastapi import Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from vlnpilot.core.commands import COMMANDS, get_command
from vlnpilot.core.decision import DecisionFields, EarlierTurn, PilotInput, Usage
from vlnpilot.core.errors import ConfigError, UnknownNameError, VLNPilotError
from vlnpilot.core.fsm import ASKED_STATES, PROFILES, parse_state
from vlnpilot.pilots.base import Pilot, PilotError, make_pilot
from vlnpilot.pilots.options import MAX_HISTORY
from vlnpilot.pilots.secrets import redact
from vlnpilot.pilots.transport import TRANSIENT_REASONS
from vlnpilot.server import images
from vlnpilot.server.images import (
    IMAGE_MIN_LENGTH,
    IMAGE_PATTERN,
    MAX_IMAGE_SIDE,  # noqa: F401
)
from vlnpilot.server.net import check_port_free
from vlnpilot.server.pool import DEFAULT_MAX_CACHED, PilotPool, check_specs, refuse_privileged
from vlnpilot.tasks.task import MAX_QUERY_CHARS

log = logging.getLogger(__name__)

TOKEN_ENV = "VLN_PILOT_TOKEN"
DEFAULT_MAX_BODY_BYTES = 8 * 1024 * 1024


# ------------------------------------------------------------------------------------------ wire models

def _tiny_jpeg_b64() -> str:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (8, 6), (120, 140, 160)).save(buf, format="JPEG", quality=70)
    return base64.b64encode(buf.getvalue()).decode("ascii")


if TYPE_CHECKING:  # built from the FSM's and the command table's values at run time; plain strings to mypy
    AskedState = str
    CommandCode = str
else:
    AskedState = Literal[tuple(s.value for s in ASKED_STATES)]
    CommandCode = Literal[tuple(COMMANDS)]
Profile = Literal[PROFILES]  # type: ignore[valid-type]


def _whole_float_to_int(value: Any) -> Any:
    """JSON Schema's "integer" includes 7.0; strict pydantic would refuse it, so the two disagreed."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


WholeNumber = Annotated[int, BeforeValidator(_whole_float_to_int)]


class EarlierTurnRequest(BaseModel):
    """One earlier turn of the client's conversation (the `history` option): what it asked then, what it answered."""

    model_config = ConfigDict(extra="forbid", strict=True)

    step: WholeNumber = Field(ge=0, le=1_000_000)
    state: AskedState
    previous_movement: CommandCode | None = None
    answer: str = Field(max_length=20_000, description="the model's own reply text at that step")
    image: str | None = Field(default=None, min_length=8, pattern=IMAGE_PATTERN,
                              description="that step's image (base64 JPEG or PNG), or null when it is not sent again")
    feedback: list[str] = Field(default_factory=list, max_length=20)
    context: list[str] = Field(default_factory=list, max_length=20)
    in_state: str | None = Field(default=None, max_length=1000)


class DecideRequest(BaseModel):
    """One step's inputs (the paper's five, plus the FSM profile, controller feedback and the pilot to ask)."""

    model_config = ConfigDict(extra="forbid", strict=True, json_schema_extra={"examples": [{
        "image": _tiny_jpeg_b64(), "query": "Go to the kitchen", "state": "Recognize Room",
        "topological_map": {"nodes": [{"id": "hall", "name": "Hall"}, {"id": "kitchen", "name": "Kitchen"}],
                            "edges": [{"from": "hall", "to": "kitchen"}]},
        "previous_movement": None}]})

    image: str = Field(description="front camera image: base64 JPEG or PNG (a data: URL is accepted)",
                       min_length=IMAGE_MIN_LENGTH, pattern=IMAGE_PATTERN, json_schema_extra={"format": "base64-image"})
    query: str = Field(description="the user's query", min_length=1, max_length=MAX_QUERY_CHARS)
    topological_map: dict[str, Any] = Field(description="rooms (nodes) and open doors (edges), as JSON")
    state: AskedState = Field(description="current FSM state (Start and Final are never asked)")
    previous_movement: CommandCode | None = Field(default=None, description="previous command code, or null")
    profile: Profile = Field(default="paper", description="FSM profile: which moves each state allows")
    feedback: list[str] = Field(default_factory=list, description="controller feedback lines for a re-ask",
                                max_length=20)
    context: list[str] = Field(default_factory=list, max_length=20,
                               description="pilot context lines (odometry, budget, memory, range readings)")
    step: WholeNumber = Field(default=0, ge=0, le=1_000_000, description="step number in the episode")
    in_state: str | None = Field(default=None, max_length=1000,
                                 description="the moves flown in the current state, as the controller states them")
    history: list[EarlierTurnRequest] | None = Field(
        default=None, max_length=MAX_HISTORY, description="earlier turns of the conversation, oldest first (the "
        "client's `history` option); the server remembers nothing between requests")
    pilot: str | None = Field(default=None, description="pilot SPEC (name or name:model); default: the server's",
                              max_length=200)
    mission: dict[str, Any] | None = Field(default=None, description="a mission of several stages "
                                           "(vlnpilot.tasks.mission.Mission.to_dict), or null")
    stage: WholeNumber = Field(default=0, ge=0, le=100, description="the mission's current stage, from 0")


class DecideResponse(DecisionFields):
    """The pilot's Decision: the paper's five fields, plus usage and the model that answered."""

    usage: Usage
    model: str | None = None
    raw_text: str | None = None


class ErrorBody(BaseModel):
    """Every error response: a message, a short reason code, and whether asking again can help."""

    detail: str
    reason: str
    fatal: bool = False
    errors: list[dict[str, Any]] | None = None  # field errors of a 422
    raw_text: str | None = None  # the model's unusable reply (502 with a reply reason)
    usage: Usage | None = None


class Health(BaseModel):
    status: str
    pilot: str


class ApiError(Exception):
    def __init__(self, status: int, detail: str, reason: str, *, fatal: bool = False,
                 headers: dict[str, str] | None = None, **extra: Any):
        super().__init__(detail)
        self.status, self.detail, self.reason, self.fatal = status, detail, reason, fatal
        self.headers = headers
        self.extra = extra


def _error_response(status: int, body: ErrorBody, headers: dict[str, str] | None = None) -> JSONResponse:
    return JSONResponse(status_code=status, content=body.model_dump(mode="json", exclude_none=True), headers=headers)


_ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorBody} for code in (400, 401, 403, 413, 415, 422, 502, 503)}


# ------------------------------------------------------------------------------------------ body limit

class BodyLimitMiddleware:
    """Answer 413 to a request body over `max_bytes` (by Content-Length, or counted while streaming)."""

    def __init__(self, app: Any, max_bytes: int):
        self.app, self.max_bytes = app, max_bytes

    async def _too_large(self, send: Any) -> None:
        body = ErrorBody(detail=f"request body over the limit of {self.max_bytes} bytes", reason="too_large",
                         fatal=True).model_dump_json(exclude_none=True).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http" or scope.get("method") in ("GET", "HEAD", "OPTIONS"):
            await self.app(scope, receive, send)
            return
        for name, value in scope.get("headers", ()):
            if name == b"content-length":
                try:
                    declared = int(value)
                except ValueError:
                    declared = 0
                if declared > self.max_bytes:
                    await self._too_large(send)
                    return
        chunks: list[bytes] = []
        total = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":  # client went away
                return
            chunk = message.get("body", b"")
            total += len(chunk)
            if total > self.max_bytes:
                await self._too_large(send)
                return
            chunks.append(chunk)
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        sent = False

        async def replay() -> Any:
            nonlocal sent
            if not sent:
                sent = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


# ------------------------------------------------------------------------------------------ decoding

@contextlib.contextmanager
def _image_errors() -> Iterator[None]:
    """A bad image is a 422 on the field `image`, in the shape of the schema's own field errors."""
    try:
        yield
    except images.BadImage as exc:
        raise ApiError(422, str(exc), "bad_image", fatal=True,
                       errors=[{"loc": ["body", "image"], "msg": str(exc), "type": "bad_image"}]) from None


def decode_image(data: str) -> np.ndarray:
    """A base64 JPEG or PNG (optionally a data: URL) as an HxWx3 uint8 RGB array; ApiError 422 otherwise."""
    with _image_errors():
        return images.decode_image(data)


def _pilot_input(req: DecideRequest, image: np.ndarray) -> PilotInput:
    try:
        state = parse_state(req.state)
    except UnknownNameError as exc:
        raise ApiError(422, str(exc), "bad_state") from None
    if state not in ASKED_STATES:
        raise ApiError(422, f"the pilot is never asked in state '{state.value}'; asked states: "
                            f"{', '.join(s.value for s in ASKED_STATES)}", "bad_state")
    if req.profile not in PROFILES:
        raise ApiError(422, f"unknown FSM profile {req.profile!r}; valid: {', '.join(PROFILES)}", "bad_profile")
    previous = req.previous_movement
    if previous is not None and previous.strip():
        try:
            previous = get_command(previous).code
        except UnknownNameError as exc:
            raise ApiError(422, str(exc), "bad_movement") from None
    else:
        previous = None
    # Always a tuple: a pilot of the server (shared by its clients) never keeps a conversation of its own.
    history = tuple(_earlier_turn(t) for t in req.history or ())
    return PilotInput(image=image, query=req.query, topological_map=req.topological_map, state=state,
                      previous_movement=previous, step=req.step, profile=req.profile,
                      feedback=tuple(str(f)[:500] for f in req.feedback),
                      context=tuple(str(c)[:500] for c in req.context), in_state=req.in_state, history=history,
                      mission=req.mission, stage=req.stage)


def _earlier_turn(turn: EarlierTurnRequest) -> EarlierTurn:
    return EarlierTurn(step=turn.step, state=parse_state(turn.state), previous_movement=turn.previous_movement,
                       answer=turn.answer, image=None if turn.image is None else decode_image(turn.image),
                       feedback=tuple(str(f)[:500] for f in turn.feedback),
                       context=tuple(str(c)[:500] for c in turn.context), in_state=turn.in_state)


# ------------------------------------------------------------------------------------------ the app

def create_app(
    pilot_factory: Callable[..., Pilot] = make_pilot,
    token: str | None = None,
    max_body_bytes: int = DEFAULT_MAX_BODY_BYTES,
    *,
    pilot_spec: str = "openai",
    allowed_pilots: Collection[str] | None = None,
    pilot_options: dict[str, Any] | None = None,
    max_cached_pilots: int = DEFAULT_MAX_CACHED,
) -> FastAPI:
    """The pilot server as an ASGI app.

    `pilot_factory(spec, **pilot_options)` builds a pilot (on first use, then kept in a bounded cache that
    closes what it evicts); `pilot_spec` is the default when a request names none; a request may name another
    SPEC only if it is in `allowed_pilots` ('openai' and 'openai:gpt-4.1' are the same SPEC); anything else
    gets 403. Pilots that need ground truth (the oracle) are refused with a ConfigError.
    `token`: if set, every /v1 request needs `Authorization: Bearer <token>` (None: no auth, and the OpenAPI
    document declares none).
    """
    refuse_privileged([pilot_spec, *(allowed_pilots or ())])
    pool = PilotPool(pilot_factory, [pilot_spec, *(allowed_pilots or ())], pilot_options, max_cached_pilots)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        yield
        pool.close()  # the SDK clients' sockets and pools

    app = FastAPI(
        lifespan=lifespan,
        title="VLN-Pilot server",
        version="1",
        description="Ask a vision-language pilot for the next drone movement (the paper's VLLM server).",
    )
    app.add_middleware(BodyLimitMiddleware, max_bytes=max_body_bytes)
    app.state.pilot_spec = pilot_spec
    app.state.pilots = pool
    pixels = images.PixelBudget()
    _document_allowed_pilots(app, pool.allowed)
    bearer = HTTPBearer(auto_error=False, description=f"the server's token (env {TOKEN_ENV})")

    def check_token(credentials: HTTPAuthorizationCredentials | None = Depends(bearer)) -> None:  # noqa: B008
        if token is None:
            return
        given = credentials.credentials if credentials is not None else ""
        if not given or not hmac.compare_digest(given.encode(), token.encode()):
            raise ApiError(401, "missing or wrong bearer token" + (f" (set {TOKEN_ENV} on the client)"),
                           "unauthorized", fatal=True, headers={"WWW-Authenticate": "Bearer"})

    def allowed_spec(requested: str | None) -> str:
        """The allowed SPEC a request names (403 otherwise): checked before anything costs memory."""
        spec = pool.resolve((requested or pilot_spec).strip())
        if spec is None:
            raise ApiError(403, f"pilot {(requested or '')[:80]!r} is not served here; allowed: "
                                f"{', '.join(pool.allowed)}", "pilot_not_allowed", fatal=True)
        return spec

    def get_pilot(spec: str) -> Pilot:
        try:
            return pool.get(spec)
        except UnknownNameError as exc:
            raise ApiError(422, str(exc), "bad_pilot") from None
        except PilotError as exc:
            raise _pilot_error(exc) from None
        except VLNPilotError as exc:
            raise ApiError(422, f"cannot build pilot {spec!r}: {exc}", "bad_pilot") from None

    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError) -> JSONResponse:
        return _error_response(exc.status, ErrorBody(detail=exc.detail, reason=exc.reason, fatal=exc.fatal,
                                                     **exc.extra), exc.headers)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        content_type = request.headers.get("content-type", "")
        if request.method == "POST" and content_type and not _is_json(content_type):
            return _error_response(415, ErrorBody(detail=f"expected Content-Type: application/json, got "
                                                         f"{content_type[:80] or 'none'!r}",
                                                  reason="unsupported_media_type", fatal=True))
        errors = [{"loc": [str(p) for p in e.get("loc", ())], "msg": str(e.get("msg", "")), "type": str(e.get("type"))}
                  for e in exc.errors()]
        detail = "; ".join(f"{'.'.join(e['loc'][1:]) or 'body'}: {e['msg']}" for e in errors) or "invalid request"
        return _error_response(422, ErrorBody(detail=detail, reason="bad_request", fatal=True, errors=errors))

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return _error_response(exc.status_code, ErrorBody(detail=str(exc.detail), reason="http_error", fatal=True),
                               getattr(exc, "headers", None))

    @app.exception_handler(Exception)
    async def _crash(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error in %s %s", request.method, request.url.path)
        return _error_response(500, ErrorBody(detail=f"internal error ({type(exc).__name__})", reason="internal"))

    @app.get("/healthz", response_model=Health, tags=["server"])
    def healthz() -> Health:
        """Liveness: the server answers and names its default pilot (no provider call)."""
        return Health(status="ok", pilot=pilot_spec)

    auth = [Depends(check_token)] if token is not None else []  # declare auth only when it is on

    @app.post("/v1/decide", response_model=DecideResponse, responses=_ERRORS, tags=["pilot"], dependencies=auth)
    def decide(req: DecideRequest) -> DecideResponse:
        """Ask the pilot for one decision (a blocking provider call, run in the worker thread pool)."""
        spec = allowed_spec(req.pilot)  # the cheap checks first: a refused pilot never has its image decoded
        with _image_errors():
            header = images.read_header(req.image)  # format and size from the header, bounded
        with pixels.hold(header.pixels):  # until the answer: a slow provider call keeps its image alive
            with _image_errors():
                pilot_input = _pilot_input(req, images.decode(header))
            return _ask(get_pilot(spec), pilot_input, req.pilot or pilot_spec)

    _add_plan_route(app, lambda requested: get_pilot(allowed_spec(requested)), auth)
    return app


def _ask(pilot: Pilot, pilot_input: PilotInput, spec: str) -> DecideResponse:
    """One decision of a built pilot, its failures as ApiErrors."""
    try:
        decision = pilot.decide(pilot_input)
    except PilotError as exc:
        raise _pilot_error(exc) from None
    except VLNPilotError as exc:
        raise ApiError(502, f"the pilot failed: {exc}", "pilot_error") from None
    except Exception as exc:
        log.exception("pilot %r crashed", spec)
        raise ApiError(502, f"the pilot crashed ({type(exc).__name__})", "pilot_crashed") from None
    return DecideResponse(room=decision.room, movement=decision.movement, state=decision.state,
                          description=decision.description, door_position=decision.door_position,
                          usage=decision.usage, model=decision.model or pilot.model, raw_text=decision.raw_text)


def _add_plan_route(app: FastAPI, get_pilot: Callable[[str | None], Pilot], auth: list[Any]) -> None:
    # Not in the OpenAPI document yet: its request is the controller's rendered planning call (docs/missions.md),
    # and a pilot that does not plan answers 422, which the document's schema-valid-request contract would refuse.
    @app.post("/v1/plan", response_model=PlanResponse, responses=_ERRORS, tags=["pilot"], dependencies=auth,
              include_in_schema=False)
    def plan(req: PlanRequest) -> PlanResponse:
        """Ask the pilot for a mission's plan before take-off (pilots/planning.py): the answer's raw JSON text."""
        return _plan(get_pilot(req.pilot), req)


def _plan(pilot: Pilot, req: PlanRequest) -> PlanResponse:
    from vlnpilot.pilots.planning import can_plan, planning_call
    from vlnpilot.prompting.render import Prompt

    if not can_plan(pilot):
        raise ApiError(422, f"pilot {pilot.name!r} does not plan; the controller's parser plans for it",
                       "cannot_plan", fatal=True)
    prompt = Prompt(system=req.system, context=req.context, state_prompt="", step_text=req.step_text,
                    image_jpeg=b"", schema=req.json_schema)
    try:
        raw, usage = planning_call(pilot)(prompt)
    except PilotError as exc:
        raise _pilot_error(exc) from None
    except VLNPilotError as exc:
        raise ApiError(502, f"the pilot failed: {exc}", "pilot_error") from None
    return PlanResponse(raw_text=raw, usage=usage, model=pilot.model)


class PlanRequest(BaseModel):
    """The planning call (pilots/planning.plan_prompt), rendered by the controller."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    system: str = Field(description="the planning rules", min_length=1, max_length=20_000)
    context: str = Field(description="the instruction and the map", min_length=1, max_length=100_000)
    step_text: str = Field(default="", description="the take-off room and a re-ask's feedback", max_length=20_000)
    json_schema: dict[str, Any] = Field(alias="schema", description="the answer's JSON schema")
    pilot: str | None = Field(default=None, description="pilot SPEC; default: the server's", max_length=200)


class PlanResponse(BaseModel):
    raw_text: str
    usage: Usage
    model: str | None = None


def _document_allowed_pilots(app: FastAPI, allowed: list[str]) -> None:
    """List the served SPECs as the `pilot` field's enum in the OpenAPI document (validation answers 403)."""
    generate = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = generate()  # FastAPI keeps it as app.openapi_schema
        for option in schema["components"]["schemas"]["DecideRequest"]["properties"]["pilot"].get("anyOf", []):
            if option.get("type") == "string":
                option["enum"] = list(allowed)
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def _is_json(content_type: str) -> bool:
    media = content_type.split(";")[0].strip().lower()
    return media == "application/json" or (media.startswith("application/") and media.endswith("+json"))


def _pilot_error(exc: PilotError) -> ApiError:
    status = 503 if exc.reason in TRANSIENT_REASONS else 502
    extra: dict[str, Any] = {}
    if getattr(exc, "raw_text", None) is not None:
        extra["raw_text"] = exc.raw_text  # type: ignore[attr-defined]
    if isinstance(getattr(exc, "usage", None), Usage):
        extra["usage"] = exc.usage  # type: ignore[attr-defined]
    return ApiError(status, redact(exc), exc.reason, fatal=exc.fatal, **extra)


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 and localhost; anything else (0.0.0.0, a LAN address, a name) may be reachable."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def app_from_env() -> FastAPI:
    """For `uvicorn --factory vlnpilot.server.app:app_from_env`: pilot from VLN_PILOT_SPEC, token from
    VLN_PILOT_TOKEN."""
    return create_app(token=os.environ.get(TOKEN_ENV) or None, pilot_spec=os.environ.get("VLN_PILOT_SPEC", "openai"))


def serve(host: str = "127.0.0.1", port: int = 8000, pilot_spec: str = "openai", *, token: str | None = None,
          log_level: str = "info", **app_options: Any) -> None:
    """Run the pilot server with uvicorn (blocking). The token defaults to env VLN_PILOT_TOKEN."""
    import uvicorn

    token = token if token is not None else (os.environ.get(TOKEN_ENV) or None)
    if token is None and not is_loopback(host):
        raise ConfigError(f"serving on {host} without a token would let anyone who reaches it spend your API "
                          f"credit; set one, e.g. export {TOKEN_ENV}=$(openssl rand -hex 16), or bind --host 127.0.0.1")
    check_specs([pilot_spec, *app_options.get("allowed_pilots", ())])  # one line for a pilot it could never serve
    app = create_app(token=token, pilot_spec=pilot_spec, **app_options)
    check_port_free(host, port, "the pilot server")  # one line, not uvicorn's log and exit 1
    uvicorn.run(app, host=host, port=port, log_level=log_level)
