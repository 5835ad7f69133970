"""Optional dependencies: which pip extra brings each one, and the one-line error when a command lacks it.

`pip install vln-pilot` gives the simulator, the controller, the oracle and the command line. Everything else
is an extra (pyproject.toml's [project.optional-dependencies]); its modules are imported only by the code that
needs them, inside `needs(...)`, so that a missing one becomes `MissingExtraError` (exit 2 on the command line).
"""

from __future__ import annotations

import contextlib
import importlib
from collections.abc import Iterator

from vlnpilot.core.errors import VLNPilotError

# The top-level modules each extra brings (the ones vlnpilot imports); tests/test_extras.py keeps this table
# in step with pyproject.toml.
EXTRA_MODULES: dict[str, tuple[str, ...]] = {
    "openai": ("openai",),
    "gemini": ("google",),
    "anthropic": ("anthropic",),
    "server": ("fastapi", "starlette", "uvicorn", "httpx"),
    "report": ("matplotlib", "jinja2", "av"),
    "tello": ("djitellopy", "av"),
    "ray": ("ray",),
    "tokens": ("bpe_openai",),
}


class MissingExtraError(VLNPilotError, ImportError):
    """A command needs an optional dependency that is not installed; the message names the pip extra."""


def install_hint(*extras: str) -> str:
    return f"pip install 'vln-pilot[{','.join(extras)}]'"


@contextlib.contextmanager
def needs(*extras: str, what: str) -> Iterator[None]:
    """Import optional modules inside this block: a missing module of `extras` becomes one clear error."""
    wanted = {module for extra in extras for module in EXTRA_MODULES[extra]}
    try:
        yield
    except ModuleNotFoundError as exc:
        missing = (exc.name or "").partition(".")[0]
        if missing not in wanted:
            raise
        raise MissingExtraError(f"{what} needs {missing}, which is not installed: {install_hint(*extras)}") from None


def require(*extras: str, what: str) -> None:
    """Check up front that `extras` are installed (before anything flies or is written), by importing them."""
    with needs(*extras, what=what):
        for module in dict.fromkeys(m for extra in extras for m in EXTRA_MODULES[extra]):
            importlib.import_module(module)


def missing_extra_message(exc: ModuleNotFoundError) -> str | None:
    """The one line for an optional module that no `needs` block caught, or None for any other module."""
    missing = (exc.name or "").partition(".")[0]
    extras = [extra for extra, modules in EXTRA_MODULES.items() if missing in modules]
    if not extras:
        return None
    return f"{missing} is not installed: {' or '.join(install_hint(extra) for extra in extras)}"
