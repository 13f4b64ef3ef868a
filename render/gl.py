"""The one place that picks the OpenGL platform, before pyrender (or PyOpenGL) is first imported.

Platform: ``PYOPENGL_PLATFORM`` when it is set; else EGL when the machine has a GPU render node
and an EGL library (hardware rasterisation), else OSMesa (software, any machine).  What was
chosen, and the GL renderer string, are printed by ``python -m render.gl`` and recorded by the
speed benchmark.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import glob
import os
import types

import cv2
import numpy as np

_patched = False


def _context_key():
    """The current GL context as a hashable, comparable int.

    Under OSMesa, PyOpenGL's ``contextdata.getContext()`` returns a fresh pointer object per
    call that compares unequal to the last one, so pyrender's shader cache (keyed by it) misses
    on every draw and recompiles every program every frame (~10x slower).  Keying by the
    pointer's address fixes that without touching anything else.
    """
    import OpenGL.contextdata

    ctx = OpenGL.contextdata.getContext()
    try:
        return ctypes.cast(ctx, ctypes.c_void_p).value or 0
    except (TypeError, ctypes.ArgumentError):
        return ctx


def choose_platform(environ=os.environ, devices=None, egl_library=None) -> tuple:
    """``(platform, why)``: the GL platform this process should use (see the module docstring).
    ``devices``/``egl_library`` are for tests; by default the machine is looked at."""
    asked = environ.get("PYOPENGL_PLATFORM")
    if asked:
        return asked, "PYOPENGL_PLATFORM is set"
    if devices is None:
        devices = glob.glob("/dev/dri/renderD*") + glob.glob("/dev/nvidia[0-9]*")
    if egl_library is None:
        egl_library = ctypes.util.find_library("EGL")
    if devices and egl_library:
        return "egl", f"GPU device {sorted(devices)[0]} and {egl_library}"
    return "osmesa", "no GPU render device with an EGL library: software rendering"


def gl_platform() -> str:
    """The platform this process renders with (chosen once, on the first import of pyrender)."""
    return os.environ.get("PYOPENGL_PLATFORM") or choose_platform()[0]


def import_pyrender():
    """Import pyrender on the platform :func:`choose_platform` picks (set once per process)."""
    global _patched
    if "PYOPENGL_PLATFORM" not in os.environ:
        os.environ["PYOPENGL_PLATFORM"] = choose_platform()[0]
    import pyrender
    import pyrender.shader_program as sp

    if not _patched:
        sp.OpenGL = types.SimpleNamespace(contextdata=types.SimpleNamespace(getContext=_context_key))
        _patch_transparent_order(pyrender)
        _patched = True
    return pyrender


def _patch_transparent_order(pyrender) -> None:
    """Draw translucent meshes in layers first (node name ``"shadow..."`` after the rest), then
    back to front.  pyrender sorts translucent meshes by node-origin distance only, which would
    sometimes draw a shadow lying 1 mm above the pad before the (soft-edged, translucent) pad,
    so that the depth test then hid the pad under it."""
    R = pyrender.renderer.Renderer

    def _sorted_mesh_nodes(self, scene):
        cam_loc = scene.get_pose(scene.main_camera_node)[:3, 3]
        solid, trans = [], []
        for node in scene.mesh_nodes:
            (trans if node.mesh.is_transparent else solid).append(node)
        dist = lambda n: -np.linalg.norm(scene.get_pose(n)[:3, 3] - cam_loc)  # noqa: E731
        # ties (nodes at the same origin) are broken by name: pyrender keeps nodes in a set, whose
        # order changes from run to run, and with it the image (equal-depth fragments)
        solid.sort(key=lambda n: (dist(n), n.name or ""))
        trans.sort(key=lambda n: (1 if (n.name or "").startswith("shadow") else 0, dist(n), n.name or ""))
        return solid + trans

    R._sorted_mesh_nodes = _sorted_mesh_nodes


def render_color_depth(offscreen, scene, flags, znear: float, zfar: float) -> tuple:
    """``(rgb (H, W, 3) uint8, z (H, W) float32)`` in OpenCV's row order: colour, and depth along
    the optical axis in metres (``inf`` where nothing was drawn).  One read of each buffer."""
    from OpenGL.GL import (GL_DEPTH_COMPONENT, GL_FLOAT, GL_FRONT, GL_READ_FRAMEBUFFER, GL_RGB, GL_UNSIGNED_BYTE,
                           glBindFramebuffer, glReadBuffer, glReadPixels)

    plat = offscreen._platform
    if plat.supports_framebuffers():  # EGL: pyrender reads and converts both (0 where nothing)
        color, z = offscreen.render(scene, flags=flags)
        z = np.where(z > 0, z, np.float32(np.inf)).astype(np.float32)
        return color, z
    plat.make_current()
    r = offscreen._renderer
    r.viewport_width, r.viewport_height = offscreen.viewport_width, offscreen.viewport_height
    r.point_size = offscreen.point_size
    r.render(scene, flags)
    w, h = r.viewport_width, r.viewport_height
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0)
    glReadBuffer(GL_FRONT)
    color = np.frombuffer(glReadPixels(0, 0, w, h, GL_RGB, GL_UNSIGNED_BYTE), np.uint8).reshape(h, w, 3)
    depth = np.frombuffer(glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT), np.float32).reshape(h, w)
    plat.make_uncurrent()
    return cv2.flip(color, 0), linear_depth(cv2.flip(depth, 0), znear, zfar)


def linear_depth(depth, znear: float, zfar: float) -> np.ndarray:
    """Depth-buffer values in [0, 1] -> z in metres along the optical axis (``inf`` where 1)."""
    d = np.asarray(depth, np.float32)
    den = d * np.float32(-2.0 * (zfar - znear))
    den += np.float32(2.0 * zfar)
    with np.errstate(divide="ignore"):
        z = np.divide(np.float32(2.0 * znear * zfar), den, out=den)
    z[d >= 1.0] = np.inf
    return z


def render_color(offscreen, scene, flags):
    """Colour only.  Under OSMesa pyrender reads back the depth buffer as well, and converts it
    to metres, on every render; that was a third of the render time for an image nobody reads."""
    plat = offscreen._platform
    if plat.supports_framebuffers():
        color, _ = offscreen.render(scene, flags=flags)
        return color
    plat.make_current()
    r = offscreen._renderer
    r.viewport_width, r.viewport_height = offscreen.viewport_width, offscreen.viewport_height
    r.point_size = offscreen.point_size
    r.render(scene, flags)
    color = np.ascontiguousarray(r.read_color_buf())
    plat.make_uncurrent()
    return color


def translucent_texture(texture):
    """Mark a texture with an alpha channel as translucent.

    pyrender caches ``Texture.is_transparent`` as False before the source is set, so a mesh whose
    transparency comes from its texture's alpha is sorted with the opaque meshes.  It is still
    blended (that follows ``alphaMode``), but it may be drawn *before* the ground behind it, and
    its transparent texels then write depth: the ground disappears there (the sky colour shows).
    Translucent meshes must be drawn after every opaque one."""
    texture._is_transparent = True
    return texture


if __name__ == "__main__":  # python -m render.gl : which platform this machine renders with
    plat, why = choose_platform()
    print(f"platform: {plat} ({why})")
    pr = import_pyrender()
    r = pr.OffscreenRenderer(8, 8)
    from OpenGL.GL import GL_RENDERER, GL_VERSION, glGetString

    r._platform.make_current()
    print(f"renderer: {glGetString(GL_RENDERER).decode()}; OpenGL {glGetString(GL_VERSION).decode()}")
    r.delete()
