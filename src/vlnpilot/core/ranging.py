"""Range sensors a drone may carry (`--sensors`): what each one measures, its limits, and how a reading is told.

One table (`SENSORS`) for the simulator's ray casts, the Tello backend, the prompts and the docs
(docs/perception.md gives the sources of each number). A pilot is told only what its drone has.
"""

from __future__ import annotations

from dataclasses import dataclass

from vlnpilot.core.errors import ConfigError
from vlnpilot.core.tello_spec import LENGTH

FRONT_BEAM_START_M = LENGTH / 2 + 0.002  # the front beam leaves at the camera's lens, ahead of the drone's centre
TT_TOF_BEYOND_MM = 8192  # what the RoboMaster TT answers to `EXT tof?` when nothing is within range (SDK 3.0 guide)


@dataclass(frozen=True)
class RangeSensor:
    """A set of single-beam time-of-flight rangers on the drone: one per direction, the same limits for each."""

    name: str
    directions: tuple[str, ...]  # front | left | right | back | up, in the drone's frame
    min_m: float  # below this the sensor cannot measure (reported as the minimum)
    max_m: float  # beyond this it reports nothing: "beyond max_m"
    noise_fraction: float  # 1-sigma noise, as a fraction of the distance
    noise_floor_m: float  # 1-sigma noise at the shortest distances
    shown_as: str  # how the prompt names it

    def sigma(self, distance: float) -> float:
        return max(self.noise_floor_m, self.noise_fraction * distance)


SENSORS: dict[str, RangeSensor | None] = {
    "none": None,
    # The RoboMaster TT's open-source controller: one ToF beam forward at the camera (VL53L0X class, default mode:
    # reliable to 1.2 m, +-3 %).
    "tof": RangeSensor("tof", ("front",), 0.03, 1.2, 0.03, 0.005,
                       "one forward time-of-flight beam beside the camera, as on the RoboMaster TT"),
    # The Crazyflie Multi-ranger deck: five VL53L1x beams, 0.04 to 4 m, a few millimetres of noise.
    "multiranger": RangeSensor("multiranger", ("front", "left", "right", "back", "up"), 0.04, 4.0, 0.0, 0.005,
                               "five time-of-flight beams, front, left, right, back and up, as the Crazyflie "
                               "Multi-ranger deck"),
}


def range_sensor(name: str | None) -> RangeSensor | None:
    """The sensor set named by `--sensors` (None for `none`); a bad name is a one-line ConfigError."""
    key = (name or "none").strip().lower()
    if key not in SENSORS:
        raise ConfigError(f"unknown --sensors {name!r}; valid: {', '.join(SENSORS)}")
    return SENSORS[key]


def forward_range(name: str | None) -> bool:
    """Whether the sensor set named by `--sensors` has a forward beam (what licenses longer approach moves)."""
    sensor = range_sensor(name)
    return sensor is not None and "front" in sensor.directions


@dataclass(frozen=True)
class RangeReading:
    """One beam's reading: `metres` None when nothing is within `max_m`."""

    direction: str
    metres: float | None
    max_m: float

    def text(self) -> str:
        return f"beyond {self.max_m:g} m" if self.metres is None else f"{self.metres:.2f} m"

    def as_dict(self) -> dict[str, float | None]:
        return {"m": None if self.metres is None else round(self.metres, 4), "max_m": self.max_m}


def readings_text(readings: tuple[RangeReading, ...]) -> str:
    """'front 0.84 m, left beyond 4 m' for the prompt."""
    return ", ".join(f"{r.direction} {r.text()}" for r in readings)


def tof_reading(answer: str, sensor: RangeSensor) -> RangeReading:
    """The TT's answer to `EXT tof?` ('tof 523', mm; 8192 beyond range) as a front reading."""
    words = answer.split()
    try:
        mm = int(words[-1])
    except (IndexError, ValueError):
        raise ValueError(f"unreadable answer to 'EXT tof?': {answer!r}") from None
    beyond = mm >= TT_TOF_BEYOND_MM or mm / 1000 > sensor.max_m
    return RangeReading("front", None if beyond else mm / 1000, sensor.max_m)
