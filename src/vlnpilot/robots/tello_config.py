"""Settings of the real-Tello backend: network ports, safety limits and the rc-pulse calibration.

Defaults live in `tello.yaml` beside this module (one source); `VLN_PILOT_TELLO_CONFIG` names a user's copy.
"""

from __future__ import annotations

import ipaddress
import os
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from vlnpilot.core.errors import ConfigError

DEFAULTS = Path(__file__).with_name("tello.yaml")
ENV_VAR = "VLN_PILOT_TELLO_CONFIG"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class RcPulse(_Strict):
    """One calibrated 10 cm move: an rc velocity held for a time, then hover."""

    speed: int = Field(ge=10, le=100)
    duration_s: float = Field(gt=0, le=3)
    settle_s: float = Field(ge=0, le=5)


class Calibration(_Strict):
    forward_10cm: RcPulse
    left_10cm: RcPulse
    right_10cm: RcPulse
    move_settle_s: float = Field(ge=0, le=5)
    yaw_tolerance_deg: float = Field(gt=0, le=30)


class TelloConfig(_Strict):
    host: str = "192.168.10.1"  # the Tello's address on its own Wi-Fi
    command_port: int = Field(8889, ge=1, le=65535)  # where the Tello listens
    local_port: int = Field(9000, ge=1, le=65535)  # our reply port (not 8889, so an emulator can share the host)
    state_port: int = Field(8890, ge=1, le=65535)  # the Tello sends state here
    video_port: int = Field(11111, ge=1, le=65535)  # and video here
    connect_timeout_s: float = Field(3.0, gt=0)
    reply_timeout_s: float = Field(7.0, gt=0)  # for a motion's "ok" (a 50 cm move takes about 2 s)
    # The Tello lands by itself 15 s after its last command: a lost `takeoff` reply is waited on 8 s at most, so
    # that the state check and the climb that follow still come well inside those 15 s.
    takeoff_timeout_s: float = Field(8.0, gt=0, le=10)
    frame_timeout_s: float = Field(5.0, gt=0)
    flight_height_m: float | None = None  # None: the scene's flight altitude
    calibration: Calibration
    takeoff_battery_pct: int = Field(ge=0, le=100)
    land_battery_pct: int = Field(ge=0, le=100)
    max_flight_s: float = Field(gt=0)
    geofence_m: float = Field(gt=0)
    keepalive_s: float = Field(gt=0, le=10)
    video_latency_s: float = Field(ge=0, le=5)
    link_silence_s: float = Field(gt=0, le=1.5)  # at most 1.5 s, so that `land` goes out within 2 s of a death
    video_silence_s: float = Field(gt=0, le=3)  # no frame this long in flight: the pilot is blind, land
    land_confirm_s: float = Field(gt=0, le=10)
    ext_tof: bool = False  # a RoboMaster TT (Tello Talent): its open-source controller answers `EXT tof?`

    @property
    def query_timeout_s(self) -> float:
        """How long a query (`battery?`, `EXT tof?`) is awaited: the Tello answers one at once, unlike a motion."""
        return min(self.reply_timeout_s, 2.0)

    @field_validator("host")
    @classmethod
    def _local_host(cls, host: str) -> str:
        check_tello_host(host, "host")
        return host


def check_tello_host(host: str, what: str) -> None:
    """A Tello's address: an IP (djitellopy matches replies by the sender's address, not a name) on a local network
    (its own Wi-Fi, a router's, or the emulator's loopback): no command of a drone's ever leaves for the internet."""
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        raise ConfigError(f"{what} must be an IP address (a Tello on its own Wi-Fi is 192.168.10.1), "
                          f"got {host!r}") from None
    if not (address.is_private or address.is_loopback or address.is_link_local) or address.is_unspecified:
        raise ConfigError(f"{what} {host} is not on a local network: a Tello is at 192.168.10.1 on its own Wi-Fi, "
                          "at a private address on a router's, or the emulator at 127.0.0.1")


def load_tello_config(path: str | Path | None = None, **overrides: Any) -> TelloConfig:
    """The packaged defaults, updated by the YAML file at `path` (or $VLN_PILOT_TELLO_CONFIG), then `overrides`."""
    data = _read(DEFAULTS)
    source = path or os.environ.get(ENV_VAR)
    if source:
        data = _merge(data, _read(Path(source)))
    data = _merge(data, overrides)
    try:
        return TelloConfig(**data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise ConfigError(f"Tello settings ({source or DEFAULTS.name}): {where}: {first['msg']}") from None


def _read(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except OSError as exc:
        raise ConfigError(f"cannot read the Tello settings file {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"the Tello settings file {path} is not valid YAML: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"the Tello settings file {path} must hold a mapping of settings")
    return data


def _merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out
