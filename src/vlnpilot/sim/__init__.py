"""The embedded MuJoCo simulator (headless, CPU). Import selects the EGL backend before MuJoCo loads."""

from vlnpilot.sim import gl  # noqa: F401  (must precede any mujoco import)
from vlnpilot.sim.simulator import SimConfig, Simulator

__all__ = ["SimConfig", "Simulator"]
