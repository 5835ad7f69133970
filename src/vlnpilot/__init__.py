"""VLN-Pilot: a large vision-language model pilots an indoor drone (embedded MuJoCo simulator).

Importing the package registers the Gymnasium ids `VLNPilot/Cabin-v0` and `VLNPilot/House-v0`, so that
`gymnasium.make("VLNPilot/Cabin-v0")` works after `import vlnpilot`: by name, so that no environment module (nor
MuJoCo) loads before `gymnasium.make`, and without importing Gymnasium (a tenth of a second) for a process that
never does: registered at once if Gymnasium is loaded, else right after it is. Nothing else changes in the process:
MuJoCo's GL backend is chosen by the simulator, when it is first imported (vlnpilot/sim/gl.py).
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from importlib.metadata import PackageNotFoundError, version
from types import ModuleType
from typing import Any

try:
    __version__ = version("vln-pilot")  # written once, in pyproject.toml
except PackageNotFoundError:  # a source tree on PYTHONPATH that was never installed
    __version__ = "0+unknown"

# id: (entry point, default keyword arguments)
GYM_ENVS: dict[str, tuple[str, dict[str, Any]]] = {
    "VLNPilot/Cabin-v0": ("vlnpilot.sim.gym_env:CabinEnv", {"scene": "cabin"}),
    "VLNPilot/House-v0": ("vlnpilot.sim.house_env:HouseEnv", {}),
}


def register_gym_envs() -> None:
    """Register `GYM_ENVS` with Gymnasium (idempotent)."""
    import gymnasium

    for env_id, (entry_point, kwargs) in GYM_ENVS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point, kwargs=kwargs)


class _RegisterAfterExec(importlib.abc.Loader):
    """Gymnasium's own loader, which registers the ids once Gymnasium's package has run."""

    def __init__(self, loader: importlib.abc.Loader):
        self.loader = loader

    def __getattr__(self, name: str) -> Any:  # the rest of the loader's interface (resources, source) is its own
        return getattr(self.loader, name)

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return self.loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self.loader.exec_module(module)
        register_gym_envs()


class _GymnasiumImportWatch(importlib.abc.MetaPathFinder):
    """Steps aside at the first import of Gymnasium, handing the import machinery Gymnasium's own spec with the
    registering loader."""

    def find_spec(self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
                  ) -> ModuleSpec | None:
        if fullname != "gymnasium":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is not None and spec.loader is not None:
            spec.loader = _RegisterAfterExec(spec.loader)
        return spec


if "gymnasium" in sys.modules:
    register_gym_envs()
else:
    sys.meta_path.insert(0, _GymnasiumImportWatch())
