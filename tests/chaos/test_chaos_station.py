"""Chaos: the live station against its neighbours (issue 26): a body limit, Host and Origin checks against DNS
rebinding, and a per-run token by default, even on loopback."""

from __future__ import annotations

import socket
from pathlib import Path

import httpx
import pytest

from vlnpilot.live.control import LiveControl
from vlnpilot.live.station import LiveStation, live_control
from vlnpilot.scene import load_scene

pytestmark = pytest.mark.chaos


@pytest.fixture
def station(tmp_path: Path, monkeypatch) -> LiveStation:
    monkeypatch.delenv("VLN_LIVE_TOKEN", raising=False)
    with LiveStation(tmp_path, control=LiveControl(pilot=None), port=0) as s:  # type: ignore[arg-type]
        yield s


def control(station: LiveStation, *, token: str | None = None, **headers: str) -> httpx.Response:
    if token:
        headers["Authorization"] = f"Bearer {token}"
    return httpx.post(f"{station.url}api/control", json={"run": Path(station.url).name, "action": "pause"},
                      headers=headers, timeout=10)


def test_a_controlling_station_has_a_token_by_default_even_on_loopback(station) -> None:
    assert station.token and len(station.token) >= 16
    assert station.page_url == f"{station.url}#token={station.token}"
    assert control(station).status_code == 401  # another local process cannot fly
    assert control(station, token=station.token).status_code != 401


def test_each_run_gets_its_own_token(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.delenv("VLN_LIVE_TOKEN", raising=False)
    tokens = []
    for _ in range(2):
        with LiveStation(tmp_path, control=LiveControl(pilot=None), port=0) as s:  # type: ignore[arg-type]
            tokens.append(s.token)
    assert tokens[0] != tokens[1]


def test_the_run_prints_the_address_with_its_token(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.delenv("VLN_LIVE_TOKEN", raising=False)
    said: list[str] = []
    with live_control(tmp_path, None, load_scene("cabin"), host="127.0.0.1", port=0, say=said.append):
        pass
    assert len(said) == 1 and "#token=" in said[0] and said[0].split("#token=")[1].split()[0]


def _announce_a_huge_body(station: LiveStation, *extra: str) -> bytes:
    """POST /api/control announcing a 5 MB body and sending none of it: the server must answer from the headers
    alone. (Sending the body raced the server's early answer and close: the client sometimes saw a reset.)"""
    host, port = station.url.split("//", 1)[1].strip("/").rsplit(":", 1)
    head = "\r\n".join(["POST /api/control HTTP/1.1", f"Host: {host}:{port}", "Content-Type: application/json",
                         "Content-Length: 5000030", *extra, "Connection: close", "", ""])
    with socket.create_connection((host, int(port)), timeout=30) as sock:
        sock.sendall(head.encode())
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
    return answer


def test_a_big_anonymous_body_is_refused_before_it_is_read(station) -> None:
    anonymous = _announce_a_huge_body(station)
    status, _, body = anonymous.partition(b"\r\n\r\n")
    assert status.startswith(b"HTTP/1.1 401") and len(body) < 200  # answered unread: nothing validated or echoed
    signed = _announce_a_huge_body(station, f"Authorization: Bearer {station.token}")
    status, _, body = signed.partition(b"\r\n\r\n")
    assert status.startswith(b"HTTP/1.1 413") and len(body) < 300


@pytest.mark.parametrize("host", ["evil.example", "evil.example:8765", "127.0.0.1.nip.io", "192.168.1.20"])
def test_a_foreign_host_name_is_refused_dns_rebinding(station, host) -> None:
    for response in (httpx.get(f"{station.url}api/meta", headers={"Host": host}, timeout=10),
                     control(station, token=station.token, Host=host)):
        assert response.status_code == 421, (host, response.status_code)


@pytest.mark.parametrize("host", ["localhost", "127.0.0.1", "127.0.0.2"])
def test_loopback_names_are_answered(station, host) -> None:
    port = station.url.rsplit(":", 1)[1].strip("/")
    assert httpx.get(f"{station.url}api/meta", headers={"Host": f"{host}:{port}"}, timeout=10).status_code == 200


def test_a_foreign_origin_cannot_control_or_read(station) -> None:
    evil = {"Origin": "http://evil.example"}
    assert control(station, token=station.token, **evil).status_code == 403
    assert httpx.get(f"{station.url}api/meta", headers=evil, timeout=10).status_code == 403
    own = {"Origin": station.url.rstrip("/")}
    assert control(station, token=station.token, **own).status_code not in (401, 403)
