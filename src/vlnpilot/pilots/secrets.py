"""API keys: where a pilot finds its key, and how a key is kept out of messages, logs and recordings.

A pilot holds its key as pydantic's `SecretStr` (its repr and str never show it); `redact` and `scrub` remove a
key, or anything shaped like one, from text a provider echoes back.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from typing import TypeVar

from vlnpilot.pilots.base import PilotError

_KEY_PATTERNS = re.compile(
    r"(sk-ant-[A-Za-z0-9_\-]{6,}|sk-[A-Za-z0-9_\-]{6,}|AIza[0-9A-Za-z_\-]{20,}|(?<=Bearer )[A-Za-z0-9._\-]{8,})"
)


def redact(text: object, *secrets: str | None) -> str:
    """`text` with the given secrets and anything shaped like an API key replaced by '***'."""
    out = str(text)
    for secret in secrets:
        if secret and len(secret) >= 4:
            out = out.replace(secret, "***")
    return _KEY_PATTERNS.sub("***", out)


_E = TypeVar("_E", bound=BaseException)


def scrub(exc: _E, *secrets: str | None) -> _E:
    """Remove secrets from an exception's message in place (a provider may echo the key back)."""
    if exc.args and any(s and len(s) >= 4 and s in str(a) for s in secrets for a in exc.args):
        exc.args = tuple(redact(a, *secrets) if isinstance(a, str) else a for a in exc.args)
    return exc


def resolve_api_key(
    api_key: str | None, env_vars: Iterable[str], provider: str, *, optional: bool = False
) -> str | None:
    """The explicit key, else the first env var that is set; a missing key is fatal and names the env vars."""
    if api_key:
        return api_key
    env_vars = tuple(env_vars)
    for var in env_vars:
        value = os.environ.get(var, "").strip()
        if value:
            return value
    if optional:
        return None
    raise PilotError(
        f"no {provider} API key: set {' or '.join(env_vars)} (or pass the api_key option)",
        fatal=True, reason="missing_key",
    )
