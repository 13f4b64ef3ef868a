"""The one place that picks the OpenGL platform, before pyrender (or PyOpenGL) is first imported.

Platform: ``PYOPENGL_PLATFORM`` when it is set; else EGL when the machine has a GPU render node
and an EGL library (hardware rasterisation), else OSMesa (software, any machine).  What was
chosen, and the GL renderer string, are printed by ``python -m render.gl`` and recorded by the
speed benchmark.
"""
from __future__ import annotations

import ctypes
import functools
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


def _draw(offscreen, scene, flags) -> tuple:
    """Render ``scene`` with ``offscreen``'s renderer, its context made current (the caller reads the
    buffers, then makes it uncurrent); ``(renderer, width, height)``."""
    offscreen._platform.make_current()
    r = offscreen._renderer
    r.viewport_width, r.viewport_height = offscreen.viewport_width, offscreen.viewport_height
    r.point_size = offscreen.point_size
    r.render(scene, flags)
    return r, r.viewport_width, r.viewport_height


def render_color_depth(offscreen, scene, flags, znear: float, zfar: float) -> tuple:
    """``(rgb (H, W, 3) uint8, z (H, W) float32)`` in OpenCV's row order: colour, and depth along
    the optical axis in metres (``inf`` where nothing was drawn).  One read of each buffer.  With a
    float framebuffer (:func:`float_framebuffer`) the colour is light, float32."""
    from OpenGL.GL import (GL_DEPTH_COMPONENT, GL_FLOAT, GL_FRONT, GL_READ_FRAMEBUFFER, GL_RGB, GL_UNSIGNED_BYTE,
                           glBindFramebuffer, glReadBuffer, glReadPixels)

    plat = offscreen._platform
    if getattr(offscreen._renderer, "_hv_float_fb", None) is not None:  # light, float32 (float_framebuffer)
        color, depth = _read_float(offscreen, scene, flags, depth=True)
        return color, linear_depth(depth, znear, zfar)
    if plat.supports_framebuffers():  # EGL: pyrender reads and converts both (0 where nothing)
        color, z = offscreen.render(scene, flags=flags)
        z = np.where(z > 0, z, np.float32(np.inf)).astype(np.float32)
        return color, z
    r, w, h = _draw(offscreen, scene, flags)
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0)
    glReadBuffer(GL_FRONT)
    color = np.frombuffer(glReadPixels(0, 0, w, h, GL_RGB, GL_UNSIGNED_BYTE), np.uint8).reshape(h, w, 3)
    depth = np.frombuffer(glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT), np.float32).reshape(h, w)
    plat.make_uncurrent()
    return cv2.flip(color, 0), linear_depth(cv2.flip(depth, 0), znear, zfar)


def linear_texture(pr, linear_rgba: np.ndarray, sampler):
    """A pyrender texture whose texels are light: ``linear_rgba`` (H, W, 4) float32 in 0..1, held
    as half floats, so that its mipmaps and its filtering average light.  (pyrender's own textures
    are 8 bits of whatever they are given: a float source is truncated to bytes.)"""
    tex = _linear_texture_class(pr)(source=np.zeros((2, 2, 4), np.uint8), source_channels="RGBA", sampler=sampler)
    tex.light = np.asarray(linear_rgba, np.float32)
    return tex


@functools.lru_cache(maxsize=None)
def _linear_texture_class(pr):
    """:func:`linear_texture`'s class (made once: it subclasses the imported pyrender's Texture)."""
    from OpenGL.GL import (GL_FLOAT, GL_RGBA, GL_RGBA16F, GL_TEXTURE_MAG_FILTER, GL_TEXTURE_MIN_FILTER,
                           GL_TEXTURE_WRAP_S, GL_TEXTURE_WRAP_T, glBindTexture, glGenTextures, glGenerateMipmap,
                           glTexImage2D, glTexParameteri)

    class LinearTexture(pr.Texture):
        def _add_to_context(self):
            self._texid = glGenTextures(1)
            glBindTexture(self.tex_type, self._texid)
            src = self.light
            glTexImage2D(self.tex_type, 0, GL_RGBA16F, src.shape[1], src.shape[0], 0, GL_RGBA, GL_FLOAT,
                         np.ascontiguousarray(src[::-1]))  # (OpenGL's first row is the image's last)
            glGenerateMipmap(self.tex_type)
            for name, value in ((GL_TEXTURE_MAG_FILTER, self.sampler.magFilter),
                                (GL_TEXTURE_MIN_FILTER, self.sampler.minFilter),
                                (GL_TEXTURE_WRAP_S, self.sampler.wrapS), (GL_TEXTURE_WRAP_T, self.sampler.wrapT)):
                glTexParameteri(self.tex_type, name, value)
            glBindTexture(self.tex_type, 0)

    return LinearTexture


def float_framebuffer(offscreen) -> None:
    """Have pyrender draw ``offscreen``'s renders into a float colour buffer (RGBA32F, and a depth
    buffer): blending (the pad's soft edge, shadows) then mixes light, and nothing is rounded to 8
    bits before the camera's own tone curve.  :func:`render_color` and :func:`render_color_depth`
    read it back as float32 light."""
    from OpenGL import GL

    offscreen._platform.make_current()
    colour, depth = GL.glGenRenderbuffers(2)
    for rb, fmt in ((colour, GL.GL_RGBA32F), (depth, GL.GL_DEPTH_COMPONENT24)):
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, fmt, offscreen.viewport_width, offscreen.viewport_height)
    fb = GL.glGenFramebuffers(1)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fb)
    GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, colour)
    GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, depth)
    status = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
    GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
    offscreen._platform.make_uncurrent()
    if status != GL.GL_FRAMEBUFFER_COMPLETE:  # (an OpenGL that cannot draw float colour: say so, not draw black)
        raise RuntimeError(f"this OpenGL ({offscreen._platform.__class__.__name__}) cannot draw into a float "
                           f"framebuffer (status 0x{int(status):x}): camera.mix_in_light needs one; set "
                           "camera.mix_in_light: false to render in 8-bit display values as revision 11 did")
    offscreen._renderer._hv_float_fb = int(fb)
    R = type(offscreen._renderer)
    if getattr(R, "_hv_float_patched", False):
        return
    forward = R._configure_forward_pass_viewport

    def configure(self, flags):
        forward(self, flags)  # (its depth state), then our buffer in place of the one it bound
        fb = getattr(self, "_hv_float_fb", None)
        if fb is not None:
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb)

    R._configure_forward_pass_viewport = configure
    R._hv_float_patched = True


def _read_float(offscreen, scene, flags, depth: bool) -> tuple:
    """``(light (H, W, 3) float32, depth-buffer values (H, W) or None)`` of a render into the float
    framebuffer (:func:`float_framebuffer`), in OpenCV's row order."""
    from OpenGL.GL import (GL_COLOR_ATTACHMENT0, GL_DEPTH_COMPONENT, GL_FLOAT, GL_READ_FRAMEBUFFER, GL_RGB,
                           glBindFramebuffer, glReadBuffer, glReadPixels)

    plat = offscreen._platform
    r, w, h = _draw(offscreen, scene, flags)
    glBindFramebuffer(GL_READ_FRAMEBUFFER, r._hv_float_fb)
    glReadBuffer(GL_COLOR_ATTACHMENT0)
    color = np.frombuffer(glReadPixels(0, 0, w, h, GL_RGB, GL_FLOAT), np.float32).reshape(h, w, 3)
    z = np.frombuffer(glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT), np.float32).reshape(h, w) if depth else None
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0)
    plat.make_uncurrent()
    return np.ascontiguousarray(color[::-1]), (None if z is None else np.ascontiguousarray(z[::-1]))


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
    if getattr(offscreen._renderer, "_hv_float_fb", None) is not None:  # light, float32 (float_framebuffer)
        return _read_float(offscreen, scene, flags, depth=False)[0]
    if plat.supports_framebuffers():
        color, _ = offscreen.render(scene, flags=flags)
        return color
    r, _, _ = _draw(offscreen, scene, flags)
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
