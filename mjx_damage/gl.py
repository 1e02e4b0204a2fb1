"""Headless OpenGL for MuJoCo's offscreen renderer: OSMesa by default, EGL with ``MUJOCO_GL=egl``."""

from __future__ import annotations

import os

GL_BACKENDS = ("osmesa", "egl")
DEFAULT_GL = "osmesa"  # what `make install` provides (Debian libosmesa6): software GL, no GPU or display
# System packages each backend needs on Debian (for the error message).
GL_PACKAGES = {"osmesa": "libosmesa6", "egl": "libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0"}


def gl_backend() -> str:
  """The headless OpenGL backend to render with: ``$MUJOCO_GL``, else ``$PYOPENGL_PLATFORM``
  when one names ``osmesa`` or ``egl``, else OSMesa."""
  for var in ("MUJOCO_GL", "PYOPENGL_PLATFORM"):
    name = os.environ.get(var, "").strip().lower()
    if name in GL_BACKENDS:
      return name
  return DEFAULT_GL


def ensure_gl() -> str:
  """Make ``mujoco.Renderer`` use a headless GL context; return the backend's name.

  MuJoCo picks its GL context class once, when ``mujoco`` is first imported,
  from ``MUJOCO_GL`` (unset → GLFW, which needs a display). ``mjx_damage``
  imports mujoco long before anything renders, so instead of relying on the
  environment at import time we point MuJoCo's context class at the headless
  backend here; ``mujoco.Renderer`` looks it up when it is constructed.

  Raises:
    RuntimeError: the backend's system library cannot be loaded (the message
      names the Debian package to install).
  """
  backend = gl_backend()
  platform = os.environ.setdefault("PYOPENGL_PLATFORM", backend)  # PyOpenGL reads it on first import
  if platform.strip().lower() != backend:
    raise RuntimeError(f"headless rendering: MUJOCO_GL={backend} but PYOPENGL_PLATFORM={platform}; "
                       "set both to the same backend (osmesa or egl), or unset PYOPENGL_PLATFORM")
  try:
    if backend == "osmesa":
      from mujoco.osmesa import GLContext
    else:
      from mujoco.egl import GLContext
  except Exception as e:  # ImportError, OSError, PyOpenGL's own errors when the .so is missing
    raise RuntimeError(
        f"headless rendering: cannot load the {backend} OpenGL backend ({type(e).__name__}: {e}). "
        f"Install it with `apt-get install {GL_PACKAGES[backend]}` (`make install` does this when run "
        f"as root), or choose the other backend with MUJOCO_GL={'egl' if backend == 'osmesa' else 'osmesa'}."
    ) from e
  from mujoco.rendering.classic import gl_context

  gl_context.GLContext = GLContext
  return backend
