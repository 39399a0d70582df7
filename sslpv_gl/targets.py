"""Off-screen render targets of the raster passes: colour textures plus a depth buffer, cached.

.. list-table::
   :header-rows: 1

   * - slot
     - paper
     - colour textures (RGBA32F)
     - size
   * - ``("rsm", i)``
     - Sec. 3.1
     - position (w = valid), normal, flux ``Phi_p`` of light ``i``
     - ``inject_size``^2
   * - ``"shadow"``
     - Sec. 3.3 (direct light)
     - world position (w = valid), one tile per light
     - ``rsm_size * n_lights`` x ``rsm_size``
   * - ``"shade"``
     - Sec. 3.3
     - full, subsurface, position, normal
     - camera ``width`` x ``height``

A slot keeps one target. A request with another size or number of textures
releases the old one (its contents are not reused: every pass clears its
target) and allocates anew, so that a sweep over image or map sizes does not
pile up GL memory. All textures sample NEAREST: the RSM textures are read one
texel per injected point and the shadow map with ``texelFetch``; the shading
target is only read back.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Target", "Targets"]


@dataclass(frozen=True)
class Target:
    textures: list              # the colour attachments, in attachment order
    fbo: object                 # moderngl.Framebuffer with a depth renderbuffer
    depth: object

    @property
    def size(self):
        return self.textures[0].size

    def begin(self, ctx, size):
        """Start a raster pass into this target: bind it, set the viewport to ``size``, clear colour and
        depth, blending off, depth test on."""
        self.fbo.use()
        self.fbo.viewport = (0, 0, int(size[0]), int(size[1]))
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.disable(ctx.BLEND)
        ctx.enable(ctx.DEPTH_TEST)

    def release(self):
        self.fbo.release()
        self.depth.release()
        for t in self.textures:
            t.release()


class Targets:
    """One :class:`Target` per slot, rebuilt when its size or texture count changes."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._slots = {}

    def get(self, slot, size, colours):
        """The target of ``slot``: ``colours`` RGBA32F textures of ``size = (width, height)`` and a depth buffer."""
        size = (int(size[0]), int(size[1]))
        t = self._slots.get(slot)
        if t is not None and t.size == size and len(t.textures) == colours:
            return t
        if t is not None:
            t.release()
        ctx = self.ctx
        texs = [ctx.texture(size, 4, dtype="f4") for _ in range(colours)]
        for tex in texs:
            tex.filter = (ctx.NEAREST, ctx.NEAREST)
        depth = ctx.depth_renderbuffer(size)
        t = Target(texs, ctx.framebuffer(color_attachments=texs, depth_attachment=depth), depth)
        self._slots[slot] = t
        return t
