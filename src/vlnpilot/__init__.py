"""VLN-Pilot: a large vision-language model pilots an indoor drone (embedded MuJoCo simulator).

Importing the package changes nothing in the process: MuJoCo's GL backend is chosen by the simulator, when it
is first imported (vlnpilot/sim/gl.py).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("vln-pilot")  # written once, in pyproject.toml
except PackageNotFoundError:  # a source tree on PYTHONPATH that was never installed
    __version__ = "0+unknown"
