"""The one place that picks the OpenGL platform, before pyrender is first imported."""
from __future__ import annotations

import ctypes
import os
import types

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


def import_pyrender():
    """Import pyrender with ``PYOPENGL_PLATFORM=osmesa`` unless another platform was asked for."""
    global _patched
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
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
    import numpy as np

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
