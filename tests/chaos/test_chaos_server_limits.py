"""Chaos: the pilot server spends memory last (issue 26): the pilot and the image's header are checked before a
pixel is decoded; its schema and its decoder agree on what an image is; `serve` refuses what it could never serve."""

from __future__ import annotations

import base64
import io
import socket

import jsonschema
import pytest
import uvicorn
from fastapi.testclient import TestClient
from PIL import Image, ImageFile

from cli_support import run_main
from fakes import sample_image
from vlnpilot.core.exits import BAD_INPUT
from vlnpilot.server import create_app
from vlnpilot.server.app import decode_image

pytestmark = pytest.mark.chaos


def png(width: int, height: int) -> str:
    buf = io.BytesIO()
    Image.new("RGB", (width, height)).save(buf, format="PNG", optimize=True)
    return base64.b64encode(buf.getvalue()).decode()


def body(image: str, pilot: str | None = None) -> dict:
    return {"image": image, "query": "Go to the kitchen", "topological_map": {}, "state": "Recognize Room",
            "pilot": pilot}


@pytest.fixture
def decoded(monkeypatch) -> list[tuple[int, int]]:
    """The sizes of the images Pillow decoded (ImageFile.load reads the pixels; opening reads the header)."""
    sizes: list[tuple[int, int]] = []
    load = ImageFile.ImageFile.load

    def counting(self):  # noqa: ANN001, ANN202
        sizes.append(self.size)
        return load(self)

    monkeypatch.setattr(ImageFile.ImageFile, "load", counting)
    return sizes


def test_a_pilot_not_served_is_refused_before_its_image_is_decoded(decoded) -> None:
    bomb = png(4096, 4096)  # 50 KB, 48 MB decoded: 16 of these took the server to 2.6 GB
    with TestClient(create_app(pilot_spec="test-scripted")) as c:
        response = c.post("/v1/decide", json=body(bomb, pilot="openai:not-served"))
    assert response.status_code == 403 and response.json()["reason"] == "pilot_not_allowed"
    assert decoded == []


def test_the_pixel_count_is_bounded_from_the_header_before_decoding(decoded) -> None:
    with TestClient(create_app(pilot_spec="test-scripted")) as c:
        bomb = c.post("/v1/decide", json=body(png(4096, 4096)))
        frame = c.post("/v1/decide", json=body(png(960, 720)))
    assert bomb.status_code == 422 and "pixels" in bomb.json()["detail"]
    assert bomb.json()["errors"][0]["loc"] == ["body", "image"]
    assert frame.status_code == 200
    assert set(decoded) == {(960, 720)}  # the bomb's pixels were never decoded


# ------------------------------------------------------------------------------------------ schema == decoder

def jpeg() -> str:
    buf = io.BytesIO()
    Image.fromarray(sample_image(6, 8)).save(buf, format="JPEG")
    return base64.b64encode(buf.getvalue()).decode()


def schema_accepts(image: str) -> bool:
    doc = create_app(pilot_spec="test-scripted").openapi()
    try:
        jsonschema.validate(image, doc["components"]["schemas"]["DecideRequest"]["properties"]["image"])
    except jsonschema.ValidationError:
        return False
    return True


def decoder_accepts(image: str) -> bool:
    try:
        decode_image(image)
    except Exception as exc:  # noqa: BLE001 - any refusal counts
        assert getattr(exc, "status", None) == 422, exc
        return False
    return True


@pytest.mark.parametrize("image", [
    "/9j/00000",  # the tester's: schema-valid before, refused by the decoder
    "/9j/0000", "/9j/" + "A" * 30, "iVBORw0KGgo", "iVBORw0KGgoA" + "A" * 40,
    base64.b64encode(b"\xff\xd8\xff\xe0" + b"\x00" * 8).decode(),  # a JPEG header and nothing else
    "data:image/jpeg;base64,/9j/00000",
    "SGVsbG8gd29ybGQh" * 8,  # base64, not an image
])
def test_what_the_schema_refuses_the_decoder_refuses_and_back(image: str) -> None:
    assert schema_accepts(image) is False
    assert decoder_accepts(image) is False


@pytest.mark.parametrize("wrap", [
    lambda b: b, lambda b: b.rstrip("="), lambda b: b.replace("+", "-").replace("/", "_"),
    lambda b: "data:image/jpeg;base64," + b,
])
def test_real_images_in_every_accepted_spelling_pass_both(wrap) -> None:
    image = wrap(jpeg())
    assert schema_accepts(image) and decoder_accepts(image)


# ------------------------------------------------------------------------------------------ serve

@pytest.mark.parametrize(("args", "words"), [
    (["--pilot", "nosuch"], "unknown pilot 'nosuch'"),
    (["--pilot", "test-scripted", "--allow", "nosuch:model"], "unknown pilot 'nosuch'"),
    (["--pilot", "openai:"], "nothing after ':'"),
    (["--pilot", "test-scripted", "--allow", ":gpt-4.1"], "names no pilot"),
])
def test_serve_refuses_a_pilot_it_could_never_serve(monkeypatch, capsys, args, words) -> None:
    started = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: started.append(app))
    code, _, err = run_main(monkeypatch, capsys, "serve", *args)
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1 and words in err, err
    assert started == []


def test_serve_on_a_port_in_use_is_one_line(monkeypatch, capsys) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        code, _, err = run_main(monkeypatch, capsys, "serve", "--pilot", "test-scripted", "--port", str(port))
    assert code == BAD_INPUT and len(err.strip().splitlines()) == 1 and f"127.0.0.1:{port}" in err, err
