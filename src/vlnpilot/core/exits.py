"""Exit codes of `vln-pilot` and the checks of command-line values that a framework cannot express.

    0    an episode (or every episode of a bench) was flown to an outcome: success, collision, step limit...;
         `declared` too (a final state declared without ground truth or a judge: recorded, never a success)
    2    bad input: one line on stderr names the problem and the valid choices
    3    a pilot or provider failure: an episode ended in `pilot_error` (a rejected key, an unknown model...)
    4    a robot's link failed: no reply at start-up (vlnpilot.core.errors.LinkFault), or an episode ended in
         `link_lost` (the Tello's state packets, video and replies went silent in flight; `land` was sent)
    130  interrupted (Ctrl-C or SIGTERM); what was recorded is kept and summary.json says "interrupted"
"""

from __future__ import annotations

import errno
from collections.abc import Iterable
from urllib.parse import urlsplit

from vlnpilot.core.errors import ConfigError, LinkFault

OK = 0
BAD_INPUT = 2
PILOT_ERROR = 3
LINK_FAULT = 4
INTERRUPTED = 130


def exit_code_for(outcomes: Iterable[str]) -> int:
    """LINK_FAULT when any episode ended in `link_lost`, else PILOT_ERROR when any ended in `pilot_error`, else OK."""
    seen = set(outcomes)
    if "link_lost" in seen:
        return LINK_FAULT
    return PILOT_ERROR if "pilot_error" in seen else OK


def error_exit_code(error: Exception) -> int:
    """The exit code of an error the command line reports in one line: a link fault has its own, the rest is input."""
    return LINK_FAULT if isinstance(error, LinkFault) else BAD_INPUT


def path_error_message(error: OSError) -> str | None:
    """One line for a path the file system refuses by its length (any command's file or directory argument), else
    None: every `Path.exists()` or `is_file()` raises it, so it is caught once, where errors become lines."""
    if error.errno != errno.ENAMETOOLONG:
        return None
    return (f"path too long: {shorten(str(error.filename))!r}; a file or directory name may have at most 255 bytes "
            "and a path 4095: give a shorter one")


def check_base_url(url: str | None, option: str = "--base-url") -> str | None:
    """`url` if it is an http(s) URL with a host, else ConfigError naming the option (None passes)."""
    if url is None:
        return None
    parts = urlsplit(url.strip())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ConfigError(f"{option} must be an http:// or https:// URL with a host, e.g. http://127.0.0.1:8000/v1; "
                          f"got {shorten(url)!r}")
    try:
        parts.port  # noqa: B018 - urllib checks the range (0..65535) only when it is read
    except ValueError:
        raise ConfigError(f"{option} has a port outside 1..65535, e.g. http://127.0.0.1:8000/v1; "
                          f"got {shorten(url)!r}") from None
    if parts.port == 0:
        raise ConfigError(f"{option} has port 0; a server listens on 1..65535; got {shorten(url)!r}")
    return url.strip()


def undecodable(text: str) -> str | None:
    """Where `text` holds bytes that were not UTF-8 (Python keeps them as surrogates), else None."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        raw = text[exc.start:exc.end].encode("utf-8", "surrogateescape")
        return f"byte {raw[:1].hex(' ')} at character {exc.start + 1}"
    return None


def shorten(text: str, limit: int = 80) -> str:
    """`text` cut to `limit` characters with its full length, for quoting user input in an error line."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"
