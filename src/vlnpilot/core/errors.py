"""The small error tree of VLN-Pilot. Every error a user can cause is a VLNPilotError with a clear message."""

from __future__ import annotations

from collections.abc import Iterable


class VLNPilotError(Exception):
    """Base of every error that VLN-Pilot raises on purpose; the CLI prints its message without a traceback."""


class UnknownNameError(VLNPilotError, KeyError):
    """A name (scene, spawn, room, target, pilot, ...) that is not known; the message lists the valid ones."""

    def __init__(self, kind: str, name: object, known: Iterable[str]):
        self.kind, self.name, self.known = kind, name, sorted(known)
        super().__init__(f"unknown {kind} {name!r}; valid {kind}s: {', '.join(self.known)}")

    def __str__(self) -> str:  # KeyError would quote the message
        return self.args[0]


class ConfigError(VLNPilotError, ValueError):
    """An option or value outside its valid range."""


class RenderBackendError(VLNPilotError, RuntimeError):
    """The headless OpenGL backend cannot start; the message names the library and the install command."""


class RobotHalt(VLNPilotError):
    """A real robot's safety rule ended the episode (battery, flight time, geofence, a lost reply to a move).

    Carries the last observation, whether the drone has landed (or was told to) or still hovers, waiting for the
    operator, and whether the step's command was carried out: only with evidence (a reply, a state change), so a
    move refused, never sent or unconfirmed is not recorded as executed. `outcome` is the episode's outcome.
    """

    outcome = "halted"

    def __init__(self, reason: str, observation: object = None, *, landed: bool = True, executed: bool = False):
        super().__init__(reason)
        self.observation, self.landed, self.executed = observation, landed, executed


class LinkFault(VLNPilotError):
    """The link to a robot failed: no reply, no state packets, no video, or it died in flight (its own exit code)."""


class LinkLost(RobotHalt, LinkFault):
    """The link died in flight (state packets, video and replies all silent): `land` was sent, the episode ends."""

    outcome = "link_lost"
