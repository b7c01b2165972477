"""MuJoCo drawn offscreen through OSMesa (software OpenGL, `apt-get install libosmesa6`).

The GL context is made here with mujoco.osmesa directly, never through mujoco.Renderer, whose
backend mujoco chooses from MUJOCO_GL once, at `import mujoco`: so MUJOCO_GL need not be set, and
whatever it is works unless it bound PyOpenGL to another platform (MUJOCO_GL=egl), which
rendering_available() reports.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

import mujoco
import numpy as np


@functools.lru_cache(maxsize=1)
def rendering_available() -> tuple[bool, str]:
    """(True, '') when an OSMesa GL context and a MuJoCo render context can be made here, else
    (False, why). The first call makes a tiny context to be sure; the answer is cached."""
    name = ctypes.util.find_library('OSMesa')
    try:
        ctypes.CDLL(name or 'libOSMesa.so.8')
    except OSError as err:
        return False, f'libOSMesa is not loadable ({err}); install it: apt-get install libosmesa6'
    try:
        from mujoco.osmesa import GLContext
    except Exception as err:  # ImportError, or PyOpenGL refusing another PYOPENGL_PLATFORM
        return False, f'mujoco.osmesa cannot be imported: {err}'
    try:
        renderer = OffscreenRenderer(mujoco.MjModel.from_xml_string('<mujoco/>'), 8, 8,
                                     gl_context_cls=GLContext)
        renderer.close()
    except Exception as err:
        return False, f'an OSMesa render context could not be created: {err}'
    return True, ''


def require_rendering() -> None:
    """Raise RuntimeError, saying why, when offscreen rendering is unavailable."""
    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f'offscreen rendering is unavailable: {why}')


class OffscreenRenderer:
    """mujoco.Renderer's essentials on an OSMesa context we own; close() frees both contexts."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, gl_context_cls=None,
                 max_geom: int = 4000):
        if gl_context_cls is None:
            from mujoco.osmesa import GLContext as gl_context_cls
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise ValueError(f'{width}x{height} exceeds the offscreen buffer '
                             f'{model.vis.global_.offwidth}x{model.vis.global_.offheight}')
        self.model, self.width, self.height = model, int(width), int(height)
        self._gl = None
        self._ctx = None
        try:
            self._gl = gl_context_cls(self.width, self.height)
            self._gl.make_current()
            self._ctx = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100.value)
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._ctx)
        except BaseException:
            self.close()
            raise
        self.scene = mujoco.MjvScene(model, maxgeom=max_geom)
        self.option = mujoco.MjvOption()
        self._rect = mujoco.MjrRect(0, 0, self.width, self.height)

    def update(self, data: mujoco.MjData, camera: mujoco.MjvCamera) -> None:
        mujoco.mjv_updateScene(self.model, data, self.option, None, camera,
                               mujoco.mjtCatBit.mjCAT_ALL.value, self.scene)

    def add_geom(self, gtype, size, pos, rgba, mat=None) -> mujoco.MjvGeom | None:
        """Append a decoration geom to the scene (after update); None when the scene is full."""
        if self.scene.ngeom >= self.scene.maxgeom:
            return None
        geom = self.scene.geoms[self.scene.ngeom]
        mujoco.mjv_initGeom(geom, gtype, np.asarray(size, float), np.asarray(pos, float),
                            np.eye(3).ravel() if mat is None else np.asarray(mat, float).ravel(),
                            np.asarray(rgba, np.float32))
        self.scene.ngeom += 1
        return geom

    def render(self) -> np.ndarray:
        if self._ctx is None:
            raise RuntimeError('render called after close')
        self._gl.make_current()
        mujoco.mjr_render(self._rect, self.scene, self._ctx)
        rgb = np.empty((self.height, self.width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(rgb, None, self._rect, self._ctx)
        return np.flipud(rgb).copy()     # OpenGL rows run bottom-up

    def close(self) -> None:
        if self._ctx is not None:
            with self._gl.as_current():
                self._ctx.free()
            self._ctx = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
