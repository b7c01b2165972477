"""Offscreen pictures of a recorded closed-loop interaction: an animated GIF and a contact sheet.

Rendering replays an InteractionRecord after the simulation (never inside the control loop): the
robot (record.extra['robot'], a shipped name or a description file; default the iiwa 14) at its
recorded joint positions, the person (example-robot-data's human model) posed so its
right wrist follows the recorded wrist, the wrist marker where the observer saw it (hidden while
occluded), the paths so far, and an overlay with the estimator's belief: p(k | D) per interaction
pattern, the estimated phase and whether the robot has committed.

MuJoCo draws through OSMesa (software OpenGL, `apt-get install libosmesa6`). The GL context is
made here with mujoco.osmesa directly, so it works whatever MUJOCO_GL was when mujoco was first
imported; MUJOCO_GL defaults to osmesa for any mujoco.Renderer made later in the process.
"""

from __future__ import annotations

import os

os.environ.setdefault('MUJOCO_GL', 'osmesa')

import ctypes  # noqa: E402
import ctypes.util  # noqa: E402
import functools  # noqa: E402
import re  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

from mixture_ip_ros.io.files import write_atomic  # noqa: E402
from mixture_ip_ros.io.records import InteractionRecord  # noqa: E402
from mixture_ip_ros.viz import human_model  # noqa: E402
from mixture_ip_ros.robot.description import load_description  # noqa: E402
from mixture_ip_ros.robot.scene import HUMAN_WRIST, build_spec  # noqa: E402

# Component colours (overlay bars, timeline); the k-th label gets the k-th colour.
PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
           (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
WRIST_RGBA = (0.9, 0.1, 0.1, 1.0)
FLANGE_RGBA = (0.15, 0.35, 0.95, 0.9)
TARGET_RGBA = (0.1, 0.8, 0.2, 0.45)
TARGET_MARKER = 'render_target'
KEY_LIGHT = 'render_key'
TRAIL_STEP = 0.02          # seconds between trail points
TRAIL_SECONDS = 4.0        # trail length drawn in the scene


@dataclass
class CameraView:
    """Free camera looking at `lookat` (world frame): MuJoCo's azimuth/elevation in degrees."""

    lookat: tuple = (0.62, 0.0, 0.25)
    distance: float = 2.3
    azimuth: float = -100.0
    elevation: float = -14.0

    def mjv_camera(self) -> mujoco.MjvCamera:
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = self.lookat
        cam.distance = self.distance
        cam.azimuth = self.azimuth
        cam.elevation = self.elevation
        return cam


# ---------------------------------------------------------------------------------- availability
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
        renderer = _OffscreenRenderer(mujoco.MjModel.from_xml_string('<mujoco/>'), 8, 8,
                                      gl_context_cls=GLContext)
        renderer.close()
    except Exception as err:
        return False, f'an OSMesa render context could not be created: {err}'
    return True, ''


def _require_rendering() -> None:
    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f'offscreen rendering is unavailable: {why}')


class _OffscreenRenderer:
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


# ---------------------------------------------------------------------------------- the scene
def build_render_model(width: int = 640, height: int = 480, scene: dict | None = None,
                       with_human: bool = True, pelvis_xy=None, robot=None) -> mujoco.MjModel:
    """The simulation scene (robot/scene.build_spec(**scene) with ``robot``) dressed for
    pictures: sky, floor tiles, lights, a target marker, and the human standing at pelvis_xy
    (default: across the table)."""
    spec = build_spec(**(scene or {}), robot=robot)
    # The scene's non-colliding geoms (floor, table legs, plate, screw) are visual-only; a spec
    # imported from URDF would drop them at compile time.
    spec.compiler.discardvisual = False
    spec.visual.global_.offwidth = max(int(width), 64)
    spec.visual.global_.offheight = max(int(height), 64)
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    spec.visual.headlight.specular = [0.1, 0.1, 0.1]
    # Software GL: multisampling and shadow maps each cost several times a plain frame, so the
    # animation has neither; the key frames of the contact sheet get shadows (shadows=True).
    spec.visual.quality.offsamples = 0
    spec.visual.quality.shadowsize = 2048
    spec.add_texture(name='render_sky', type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=[0.75, 0.82, 0.9],
                     rgb2=[0.25, 0.28, 0.33], width=256, height=1536)
    spec.add_texture(name='render_tiles', type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.78, 0.78, 0.76],
                     rgb2=[0.68, 0.68, 0.66], width=256, height=256)
    tiles = spec.add_material(name='render_tiles', texrepeat=[6, 6])
    tiles.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = 'render_tiles'
    for geom in spec.geoms:
        if geom.name == 'floor':
            geom.material = 'render_tiles'
            geom.rgba = [1, 1, 1, 1]
    spec.worldbody.add_light(name=KEY_LIGHT, pos=[0.6, 1.5, 2.5], dir=[0, -0.5, -1],
                             castshadow=True, diffuse=[0.5, 0.5, 0.5])
    target = spec.worldbody.add_body(name=TARGET_MARKER, mocap=True, pos=[0, 0, -5])
    target.add_site(name=TARGET_MARKER, size=[0.035, 0, 0], rgba=list(TARGET_RGBA))
    if with_human:
        human_model.add_human(spec, pelvis_xy=human_model.DEFAULT_PELVIS_XY
                              if pelvis_xy is None else pelvis_xy)
    return spec.compile()


# ---------------------------------------------------------------------------------- the record
def _validate(record: InteractionRecord, dof: int) -> None:
    def arr(name, ndim, cols=None):
        a = np.asarray(getattr(record, name), dtype=float)
        if a.ndim != ndim or (cols is not None and a.shape[1] != cols):
            want = f'(n, {cols})' if cols is not None else '(n,)'
            raise ValueError(f'record.{name} must have shape {want}, got {a.shape}')
        return a
    t, q, flange = arr('t', 1), arr('q', 2, dof), arr('flange', 2, 3)
    if t.size < 1 or q.shape[0] != t.size or flange.shape[0] != t.size:
        raise ValueError(f'record.t {t.shape}, q {q.shape} and flange {flange.shape} '
                         'must have the same, non-zero length')
    if not all(np.all(np.isfinite(a)) for a in (t, q, flange)) or np.any(np.diff(t) <= 0):
        raise ValueError('record.t must be strictly increasing and record.t, q, flange finite')
    wt, w = arr('wrist_t', 1), arr('wrist', 2, 3)
    if wt.size != w.shape[0]:
        raise ValueError(f'record.wrist_t {wt.shape} and record.wrist {w.shape} do not match')
    pt = arr('posterior_t', 1)
    if np.any(np.diff(pt) < 0) or not np.all(np.isfinite(pt)):
        raise ValueError('record.posterior_t must be finite and non-decreasing')
    K = len(record.component_labels)
    post = np.asarray(record.posterior, dtype=float)
    if pt.size and post.shape != (pt.size, K):
        raise ValueError(f'record.posterior must have shape ({pt.size}, {K}) for {pt.size} '
                         f'posterior_t and {K} component_labels, got {post.shape}')
    for name in ('phase', 'alpha'):
        if np.asarray(getattr(record, name)).reshape(-1).size != pt.size:
            raise ValueError(f'record.{name} must have one entry per posterior_t ({pt.size})')
    if record.target is not None and np.asarray(record.target, float).shape != (3,):
        raise ValueError('record.target must be None or 3 numbers')


class _Replay:
    """The record resampled at arbitrary times: what each frame shows. Positions are moved from
    the robot's base frame (the record's) to the scene's world frame (the picture's)."""

    def __init__(self, record: InteractionRecord):
        extra = record.extra if isinstance(record.extra, dict) else {}
        self.robot = load_description(extra.get('robot'))
        _validate(record, self.robot.dof)
        to_world = self.robot.base_to_world()
        self.record = record
        self.t = np.asarray(record.t, float)
        self.q = np.asarray(record.q, float)
        self.flange = to_world.apply_array(np.asarray(record.flange, float))
        self.target = (None if record.target is None
                       else to_world.apply_array(np.asarray(record.target, float)))
        wt = np.asarray(record.wrist_t, float)
        w = to_world.apply_array(np.asarray(record.wrist, float).reshape(-1, 3))
        ok = np.all(np.isfinite(w), axis=1) & np.isfinite(wt)
        self.wrist_t, self.wrist = wt[ok], w[ok]
        order = np.argsort(self.wrist_t)
        self.wrist_t, self.wrist = self.wrist_t[order], self.wrist[order]
        steps = np.diff(self.wrist_t)
        self.wrist_period = float(np.median(steps)) if steps.size else 0.01
        self.post_t = np.asarray(record.posterior_t, float)
        self.post = (np.asarray(record.posterior, float).reshape(self.post_t.size, -1)
                     if self.post_t.size else np.zeros((0, len(record.component_labels))))
        self.phase = np.asarray(record.phase, float).reshape(-1)
        self.alpha = np.asarray(record.alpha, float).reshape(-1)
        self.labels = [str(x) for x in record.component_labels]

    @property
    def origin(self) -> float:
        """Times are shown relative to the movement onset when known."""
        return float(self.record.onset_time) if self.record.onset_time is not None else self.t[0]

    def joints(self, time: float) -> np.ndarray:
        return np.array([np.interp(time, self.t, self.q[:, j]) for j in range(self.q.shape[1])])

    def wrist_observed(self, time: float) -> np.ndarray | None:
        """The wrist as last seen, if seen within 2.5 sample periods; None while occluded."""
        if self.wrist_t.size == 0:
            return None
        i = int(np.searchsorted(self.wrist_t, time, side='right')) - 1
        if i < 0 or time - self.wrist_t[i] > 2.5 * self.wrist_period:
            return None
        return self.wrist[i]

    def wrist_path(self, time: float) -> np.ndarray | None:
        """Where the person's wrist is drawn: the observed path, interpolated across gaps."""
        if self.wrist_t.size == 0:
            return None
        return np.array([np.interp(time, self.wrist_t, self.wrist[:, j]) for j in range(3)])

    def belief(self, time: float) -> int | None:
        """Index of the last estimator output at or before `time`."""
        i = int(np.searchsorted(self.post_t, time, side='right')) - 1
        return i if i >= 0 else None

    def trail(self, times: np.ndarray, values: np.ndarray, time: float) -> list[np.ndarray]:
        """The last TRAIL_SECONDS of a path up to `time`, thinned to about one point per
        TRAIL_STEP, as pieces split where samples are missing (an occlusion is not drawn)."""
        sel = (times <= time) & (times >= time - TRAIL_SECONDS)
        ts, pts = times[sel], values[sel]
        if ts.size < 2:
            return []
        period = float(np.median(np.diff(times)))
        step = max(1, int(round(TRAIL_STEP / max(period, 1e-6))))
        keep = np.arange(ts.size - 1, -1, -step)[::-1]          # always keep the newest point
        ts, pts = ts[keep], pts[keep]
        breaks = np.flatnonzero(np.diff(ts) > (step + 1.5) * period) + 1
        return [piece for piece in np.split(pts, breaks) if len(piece) > 1]


def _frame_times(replay: _Replay, fps: float) -> np.ndarray:
    t0, t1 = replay.t[0], replay.t[-1]
    return np.arange(t0, t1 + 0.5 / fps, 1.0 / fps).clip(t0, t1)


# ---------------------------------------------------------------------------------- frames
class InteractionRenderer:
    """Draws frames of one record; use as a context manager (it owns a GL context).

    With overlay, a frame is the 3D view on top and an info band below it (the estimator's belief,
    phase, status, legend), together width x height; without, the 3D view fills the frame.
    """

    def __init__(self, record: InteractionRecord, width: int = 640, height: int = 480,
                 camera: CameraView | None = None, scene: dict | None = None,
                 with_human: bool = True, overlay: bool = True):
        _require_rendering()
        self.replay = _Replay(record)
        if scene is None:
            extra_scene = record.extra.get('scene') if isinstance(record.extra, dict) else None
            scene = dict(extra_scene) if isinstance(extra_scene, dict) else {}
        self.width, self.height = int(width), int(height)
        self.overlay = overlay
        # Text about 1/34 of the frame height, smaller if the band would take over a third.
        size = max(10, min(self.height // 34, self.width // 46))
        while size > 5 and _band_height(_font(size), len(self.replay.labels)) > self.height / 3:
            size -= 1
        self._font = _font(size)
        self.band_height = _band_height(self._font, len(self.replay.labels)) if overlay else 0
        self.view_height = self.height - self.band_height
        if self.view_height < 16:
            raise ValueError(f'{width}x{height} leaves no room for the 3D view under the overlay')
        self.model = build_render_model(self.width, self.view_height, scene, with_human,
                                        robot=self.replay.robot)
        self.data = mujoco.MjData(self.model)
        self.camera = (camera or CameraView()).mjv_camera()
        self._qadr = np.array([self.model.joint(n).qposadr[0]
                               for n in self.replay.robot.joint_names])
        self._wrist_mocap = int(self.model.body(HUMAN_WRIST).mocapid[0])
        self._wrist_site = self.model.site(HUMAN_WRIST).id
        self._target_mocap = int(self.model.body(TARGET_MARKER).mocapid[0])
        self._key_light = self.model.light(KEY_LIGHT).id
        self.model.site_rgba[self._wrist_site] = WRIST_RGBA
        self.poser = human_model.HumanPoser(self.model) if with_human else None
        if self.poser is not None:
            self.poser.relax(self.data)
        self.ik_error_max = 0.0
        self._renderer = _OffscreenRenderer(self.model, self.width, self.view_height)

    def close(self) -> None:
        self._renderer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def frame(self, time: float, shadows: bool = False) -> np.ndarray:
        """RGB image (height, width, 3) uint8 of the interaction at record time `time`."""
        r, m, d = self.replay, self.model, self.data
        d.qpos[self._qadr] = r.joints(time)
        seen = r.wrist_observed(time)
        if seen is not None:
            d.mocap_pos[self._wrist_mocap] = seen
            m.site_rgba[self._wrist_site, 3] = WRIST_RGBA[3]
        else:
            m.site_rgba[self._wrist_site, 3] = 0.0
        target = r.target
        after_onset = r.record.onset_time is None or time >= r.record.onset_time
        d.mocap_pos[self._target_mocap] = (np.asarray(target, float)
                                           if target is not None and after_onset else (0, 0, -5))
        if self.poser is not None:
            goal = r.wrist_path(time)
            if goal is not None:
                # Warm-started from the previous frame's pose, so the arm moves continuously.
                self.ik_error_max = max(self.ik_error_max, self.poser.reach(d, goal))
        mujoco.mj_kinematics(m, d)
        mujoco.mj_camlight(m, d)
        m.light_castshadow[self._key_light] = bool(shadows)
        rend = self._renderer
        rend.update(d, self.camera)
        self._path(r.trail(r.wrist_t, r.wrist, time), WRIST_RGBA)
        self._path(r.trail(r.t, r.flange, time), FLANGE_RGBA)
        img = rend.render()
        if not self.overlay:
            return img
        band = _draw_band(self.replay, time, self.width, self.band_height, self._font)
        return np.concatenate([img, np.asarray(band)], axis=0)

    def _path(self, pieces: list[np.ndarray], rgba) -> None:
        # Lines, not capsules: a few hundred tessellated capsules doubled the software GL time.
        width = max(2.0, self.view_height / 120)
        line = mujoco.mjtGeom.mjGEOM_LINE
        for points in pieces:
            for a, b in zip(points[:-1], points[1:]):
                geom = self._renderer.add_geom(line, (0, 0, 0), (0, 0, 0), rgba)
                if geom is None:
                    return
                mujoco.mjv_connector(geom, line, width, a, b)


@functools.lru_cache(maxsize=8)
def _font(size: int):
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):     # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _font_size(font) -> int:
    return int(getattr(font, 'size', 11))


def _band_height(font, n_labels: int) -> int:
    size = _font_size(font)
    line = int(size * 1.4)
    return 2 * (size // 2) + line * (1 + max(n_labels, 4))


def _status(replay: _Replay, time: float) -> tuple[str, bool]:
    """(text, committed) for the band."""
    rec = replay.record
    if rec.commit_time is not None and time >= rec.commit_time:
        frac = (f' at {100 * rec.commit_fraction:.0f} %' if rec.commit_fraction is not None else '')
        return f'robot committed: {rec.chosen_pattern or "?"}{frac}', True
    if rec.onset_time is not None and time < rec.onset_time:
        return 'waiting for the person to move', False
    if rec.end_time is not None and time >= rec.end_time:
        return 'movement over, no commitment', False
    return 'observing, robot waits', False


_WHITE, _GREY, _YELLOW, _BAND = (255, 255, 255), (170, 170, 170), (255, 220, 60), (28, 30, 36)


def _draw_band(replay: _Replay, time: float, width: int, height: int, font) -> Image.Image:
    """The info band: p(k | D) bars (left); time, truth, phase, status and legend (right)."""
    rec = replay.record
    im = Image.new('RGB', (width, height), _BAND)
    draw = ImageDraw.Draw(im)
    size = _font_size(font)
    line = int(size * 1.4)
    pad = size // 2
    half = width // 2
    i = replay.belief(time)
    committed = rec.commit_time is not None and time >= rec.commit_time
    # Left column: the belief over patterns.
    y = pad
    draw.text((pad, y), 'p(pattern | wrist so far)' if i is not None else 'no estimate yet',
              font=font, fill=_GREY)
    label_w = max([int(draw.textlength(s, font=font)) for s in replay.labels] + [size * 3])
    pct_w = int(draw.textlength('100 %', font=font))
    x_bar = pad * 2 + label_w
    bar_w = max(size * 2, half - x_bar - pct_w - 2 * pad)
    probs = replay.post[i] if i is not None else np.zeros(len(replay.labels))
    for k, name in enumerate(replay.labels):
        y += line
        chosen = committed and name == rec.chosen_pattern
        draw.text((pad, y), name, font=font, fill=_YELLOW if chosen else _WHITE)
        p = float(np.clip(probs[k], 0, 1)) if np.isfinite(probs[k]) else 0.0
        top, bottom = y + line // 6, y + line - line // 4
        draw.rectangle([x_bar, top, x_bar + bar_w, bottom], outline=(110, 110, 110))
        if p > 0:
            draw.rectangle([x_bar, top, x_bar + int(round(p * bar_w)), bottom],
                           fill=PALETTE[k % len(PALETTE)])
        draw.text((x_bar + bar_w + pad, y), f'{100 * p:.0f} %', font=font, fill=_WHITE)
    # Right column.
    x, y = half + pad, pad
    head = f't = {time - replay.origin:+.2f} s'
    if rec.true_pattern is not None:
        head += f'    person: {rec.true_pattern}'
    draw.text((x, y), head, font=font, fill=_WHITE)
    y += line
    if i is not None and np.isfinite(replay.phase[i]):
        z = float(np.clip(replay.phase[i], 0, 1))
        a = replay.alpha[i]
        text = f'phase z = {z:.2f}' + (f'    T = {1 / a:.2f} s' if np.isfinite(a) and a > 0 else '')
    else:
        z, text = None, 'phase z: -'
    draw.text((x, y), text, font=font, fill=_WHITE)
    y += line
    top, bottom = y + line // 6, y + line - line // 4
    draw.rectangle([x, top, width - pad, bottom], outline=(110, 110, 110))
    if z is not None and z > 0:
        draw.rectangle([x, top, x + int(z * (width - pad - x)), bottom], fill=(190, 190, 190))
    y += line
    status, _ = _status(replay, time)
    draw.text((x, y), status, font=font, fill=_YELLOW if committed else _WHITE)
    y += line
    items = [('wrist', WRIST_RGBA), ('robot hand', FLANGE_RGBA)]
    if rec.target is not None:
        items.append(('target', TARGET_RGBA))
    for text, rgba in items:
        colour = tuple(int(255 * v) for v in rgba[:3])
        d = size * 2 // 3
        draw.ellipse([x, y + (line - d) // 2, x + d, y + (line + d) // 2], fill=colour)
        draw.text((x + d + pad // 2, y), text, font=font, fill=_GREY)
        x += d + pad + int(draw.textlength(text, font=font)) + size
    return im


# ---------------------------------------------------------------------------------- outputs
def _key_times(replay: _Replay) -> list[tuple[str, float]]:
    rec = replay.record
    t0, t1 = replay.t[0], replay.t[-1]
    keys = [('onset' if rec.onset_time is not None else 'start',
             rec.onset_time if rec.onset_time is not None else t0)]
    if rec.commit_time is not None:
        keys.append(('robot commits', rec.commit_time))
    if rec.end_time is not None:
        keys.append(('movement end', rec.end_time))
    keys.append(('handover' if rec.commit_time is not None else 'last frame', t1))
    out: list[tuple[str, float]] = []
    for name, tk in sorted(keys, key=lambda item: item[1]):
        tk = float(np.clip(tk, t0, t1))
        if out and abs(tk - out[-1][1]) < 0.15:
            continue
        out.append((name, tk))
    return out


def _timeline(replay: _Replay, width: int, height: int, keys, font) -> Image.Image:
    """p(k | D) per component and the phase over the record's time, events marked."""
    im = Image.new('RGB', (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(im)
    size = _font_size(font)
    left, right, top, bottom = size * 4, size * 12, size, size * 2 + 4
    span = max(replay.t[-1] - replay.t[0], 1e-9)

    def x_of(t):
        return left + (t - replay.t[0]) / span * (width - left - right)

    def y_of(p):
        return top + (1 - p) * (height - top - bottom)

    draw.rectangle([left, top, width - right, height - bottom], outline=(0, 0, 0))
    for p in (0, 0.5, 1):
        draw.line([left, y_of(p), width - right, y_of(p)], fill=(225, 225, 225))
        draw.text((4, y_of(p) - size // 2), f'{p:.1f}', font=font, fill=(0, 0, 0))
    for name, tk in keys:
        x = x_of(tk)
        draw.line([x, top, x, height - bottom], fill=(120, 120, 120), width=1)
        draw.text((x + 3, height - bottom + 2), name, font=font, fill=(60, 60, 60))
    if replay.post_t.size:
        for k in range(replay.post.shape[1]):
            pts = [(x_of(t), y_of(np.clip(p, 0, 1)))
                   for t, p in zip(replay.post_t, replay.post[:, k]) if np.isfinite(p)]
            if len(pts) > 1:
                draw.line(pts, fill=PALETTE[k % len(PALETTE)], width=3)
        pts = [(x_of(t), y_of(np.clip(z, 0, 1))) for t, z in zip(replay.post_t, replay.phase)
               if np.isfinite(z)]
        if len(pts) > 1:
            draw.line(pts, fill=(40, 40, 40), width=1)
    ly = top
    for k, name in enumerate(replay.labels):
        draw.line([width - right + 8, ly + size // 2, width - right + 8 + size, ly + size // 2],
                  fill=PALETTE[k % len(PALETTE)], width=3)
        draw.text((width - right + 12 + size, ly), f'p({name})', font=font, fill=(0, 0, 0))
        ly += int(size * 1.4)
    draw.line([width - right + 8, ly + size // 2, width - right + 8 + size, ly + size // 2],
              fill=(40, 40, 40), width=1)
    draw.text((width - right + 12 + size, ly), 'phase z', font=font, fill=(0, 0, 0))
    return im


def _contact_sheet(frames: list[tuple[str, float, np.ndarray]], replay: _Replay,
                   font) -> Image.Image:
    rec = replay.record
    h, w = frames[0][2].shape[:2]
    size = _font_size(font)
    line = int(size * 1.5)
    title_h = line * 2 + size
    plot_h = max(160, h // 2)
    sheet = Image.new('RGB', (w * len(frames), title_h + line + h + plot_h), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    chosen = rec.chosen_pattern if rec.chosen_pattern is not None else 'none'
    verdict = ''
    if rec.true_pattern is not None and rec.chosen_pattern is not None:
        verdict = '  (right)' if rec.true_pattern == rec.chosen_pattern else '  (WRONG)'
    title = f'{rec.name}: person does {rec.true_pattern or "?"}, robot chose {chosen}{verdict}'
    draw.text((size, size // 2), title, font=font, fill=(0, 0, 0))
    sub = []
    if rec.commit_time is not None:
        since = 'after onset' if rec.onset_time is not None else 'after the start'
        sub.append(f'committed {rec.commit_time - replay.origin:.2f} s {since}'
                   + (f' ({100 * rec.commit_fraction:.0f} % of the movement)'
                      if rec.commit_fraction is not None else ''))
    if rec.target is not None:
        miss = np.linalg.norm(replay.flange[-1] - np.asarray(rec.target, float))
        sub.append(f'final robot hand to target: {100 * miss:.1f} cm')
    draw.text((size, size // 2 + line), ';  '.join(sub), font=font, fill=(60, 60, 60))
    for j, (name, tk, img) in enumerate(frames):
        draw.text((j * w + size, title_h), f'{name}  (t = {tk - replay.origin:+.2f} s)',
                  font=font, fill=(0, 0, 0))
        sheet.paste(Image.fromarray(img), (j * w, title_h + line))
    keys = [(name, tk) for name, tk, _ in frames]
    sheet.paste(_timeline(replay, w * len(frames), plot_h, keys, font), (0, title_h + line + h))
    return sheet


def _safe_name(name: str) -> str:
    return re.sub(r'[^A-Za-z0-9_.-]+', '_', str(name)).strip('._') or 'interaction'


def render_frames(record: InteractionRecord, times, *, width: int = 640, height: int = 480,
                  camera: CameraView | None = None, scene: dict | None = None,
                  with_human: bool = True, overlay: bool = True) -> list[np.ndarray]:
    """RGB frames (height, width, 3) uint8 of `record` at the given record times (seconds).

    Raises RuntimeError when offscreen rendering is unavailable, ValueError for a bad record.
    """
    times = np.asarray(times, dtype=float).reshape(-1)
    if not np.all(np.isfinite(times)):
        raise ValueError('frame times must be finite')
    with InteractionRenderer(record, width, height, camera, scene, with_human, overlay) as r:
        return [r.frame(float(t)) for t in times]


def render_interaction(record: InteractionRecord, out_dir, *, fps: float = 25, width: int = 640,
                       height: int = 480, camera: CameraView | None = None,
                       scene: dict | None = None, with_human: bool = True) -> dict:
    """Write `<name>.gif` (the whole record at `fps` frames per simulated second, played in real
    time) and `<name>_sheet.png` (key frames: onset, commit, movement end, handover; the belief
    over time below) into out_dir. Returns {'animation': Path, 'contact_sheet': Path}.

    scene: build_spec keyword arguments (e.g. {'pole': True}); default record.extra['scene'].
    Raises RuntimeError when offscreen rendering is unavailable, ValueError for a bad record.
    """
    if not (np.isfinite(fps) and 0 < fps <= 50):    # GIF viewers slow down faster frames
        raise ValueError(f'fps must be in (0, 50], got {fps}')
    if not (16 <= int(width) <= 4096 and 16 <= int(height) <= 4096):
        raise ValueError(f'width and height must be 16..4096 pixels, got {width}x{height}')
    _require_rendering()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = _safe_name(record.name)
    gif_path, sheet_path = out / f'{stem}.gif', out / f'{stem}_sheet.png'
    with InteractionRenderer(record, width, height, camera, scene, with_human) as r:
        grid = _frame_times(r.replay, fps)
        keys = _key_times(r.replay)
        # One pass in time order (the human's IK is warm-started frame to frame): the animation
        # frames on the fps grid, the key frames at their own times.
        todo = sorted([(float(t), None) for t in grid] + [(tk, name) for name, tk in keys],
                      key=lambda item: item[0])
        frames: list[Image.Image] = []
        key_frames = []
        for t, key in todo:
            img = r.frame(t, shadows=key is not None)
            if key is not None:
                key_frames.append((key, t, img))
            else:
                # Quantize as we go: a palette image takes a third of the RGB one's memory.
                frames.append(Image.fromarray(img).quantize(
                    256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE))
        font = _font(max(11, int(height) // 30))
    write_atomic(gif_path, lambda f: frames[0].save(
        f, format='GIF', save_all=True, append_images=frames[1:],
        duration=max(20, int(round(1000 / fps))), loop=0))
    sheet = _contact_sheet(key_frames, r.replay, font)
    write_atomic(sheet_path, lambda f: sheet.save(f, format='PNG'))
    return {'animation': gif_path, 'contact_sheet': sheet_path}
