"""The embedded MuJoCo simulator (headless, CPU). Importing it chooses MuJoCo's GL backend (sim/gl.py)."""

from vlnpilot.sim.simulator import SimConfig, Simulator

__all__ = ["SimConfig", "Simulator"]
