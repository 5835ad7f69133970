"""OpenGL across `os.fork`: what a forked child (an async vector environment's worker) may render.

GL state does not survive a fork. A child inherits MuJoCo's initialised EGL display without the rasteriser threads
behind it (Mesa's llvmpipe), and its first frame waits for them forever. So, before a fork:

- a process that has rendered but has no GL context open any more (every environment closed) releases its EGL
  display; the child then initialises its own, and the parent does again at its next renderer. This is what makes
  an async vector environment work after an environment was made, reset and closed in the parent;
- a process with a context still open (or on another backend, whose state cannot be released) leaves it, and the
  child refuses to render in one line that names the fix (`FORKED`) rather than hang.
"""

from __future__ import annotations

import gc
import os
import sys
from types import ModuleType

from vlnpilot.core.errors import RenderBackendError

FORKED = ("cannot render in a process forked from one with an OpenGL context open (GL state does not survive a fork; "
          "the first frame would wait forever): make the vector environment with "
          "vector_kwargs={'context': 'spawn'}, or close every environment that has rendered before making it")

_rendered_here = False  # this process has opened a renderer since its GL state was last released
_live_at_fork = False  # the GL state the fork under way leaves to the child
_inherited_live_gl = False  # this process is such a child


def opening_renderer() -> None:
    """The simulator is about to open a renderer: refused in a child that inherited live GL state (`FORKED`)."""
    global _rendered_here
    if _inherited_live_gl:
        raise RenderBackendError(FORKED)
    _rendered_here = True


def _egl_contexts_open(egl: ModuleType) -> bool:
    """Whether any MuJoCo EGL context is open in the process, the simulator's or anyone's (a closed renderer has
    freed its context); looked for among the live objects, as MuJoCo keeps no list of them."""
    context_type = getattr(egl, "GLContext", None)
    return context_type is None or any(isinstance(o, context_type) and getattr(o, "_context", None)
                                       for o in gc.get_objects())


def _release_idle_gl() -> bool:
    """Release MuJoCo's EGL display if no context uses it; whether this process still holds live GL state."""
    egl = sys.modules.get("mujoco.egl")  # loaded by MuJoCo with MUJOCO_GL=egl
    if egl is None:  # another backend: nothing to release, and whatever rendered stays live
        return _rendered_here
    terminate = getattr(egl, "_terminate_display", None)  # MuJoCo's own, run at exit
    if getattr(egl, "EGL_DISPLAY", None) is None:
        return False  # never initialised, or released already
    if terminate is None or _egl_contexts_open(egl):
        return True
    terminate()
    return False


def _before_fork() -> None:
    global _live_at_fork, _rendered_here
    _live_at_fork = _release_idle_gl()
    _rendered_here = _live_at_fork


def _after_fork_in_child() -> None:
    global _inherited_live_gl, _rendered_here
    _inherited_live_gl = _inherited_live_gl or _live_at_fork
    _rendered_here = False


if hasattr(os, "register_at_fork"):  # not on Windows, which cannot fork
    os.register_at_fork(before=_before_fork, after_in_child=_after_fork_in_child)
