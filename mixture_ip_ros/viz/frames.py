"""Frames of a recorded closed-loop interaction, replayed after the simulation (never inside
the control loop).

A frame shows the robot (record.extra['robot'], a shipped name or a description file; default the
iiwa 14) at its recorded joint positions, the person (example-robot-data's human model) posed so
its right wrist follows the recorded wrist, the wrist marker where the observer saw it (hidden
while occluded), the paths so far, and under it the info band (viz.overlays). The green marker is
the target; where the robot takes a partner's part (record.extra['partner']: the partner's hand
over time, base frame), it is where the partner's hand was, and the person stands where
record.extra['person1'] (collar x, y, z, facing; world frame) says, on a floor under their feet.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from mixture_ip_ros.io.records import InteractionRecord
from mixture_ip_ros.robot.scene import FLOOR_Z, HUMAN_WRIST, build_spec
from mixture_ip_ros.viz import human_model
from mixture_ip_ros.viz.offscreen import OffscreenRenderer, require_rendering
from mixture_ip_ros.viz.overlays import (FLANGE_RGBA, TARGET_RGBA, WRIST_RGBA,
                                         draw_info_band, info_band_height, text_font)
from mixture_ip_ros.viz.replay import Replay

# Names of what the pictures add to the simulation scene: the target marker and a key light.
TARGET_MARKER = 'render_target'
KEY_LIGHT = 'render_key'


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


def build_render_model(width: int = 640, height: int = 480, scene: dict | None = None,
                       with_human: bool = True, pelvis_xy=None, robot=None) -> mujoco.MjModel:
    """The simulation scene (robot/scene.build_spec(**scene) with ``robot``) dressed for
    pictures: sky, floor tiles, lights, a target marker, and the human standing at pelvis_xy
    (default: across the table) on the scene's floor."""
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
                              if pelvis_xy is None else pelvis_xy,
                              floor_z=(scene or {}).get('floor_z', FLOOR_Z))
    return spec.compile()


class InteractionRenderer:
    """Draws frames of one record; use as a context manager (it owns a GL context).

    With overlay, a frame is the 3D view on top and an info band below it (the estimator's belief,
    phase, status, legend), together width x height; without, the 3D view fills the frame.
    """

    def __init__(self, record: InteractionRecord, width: int = 640, height: int = 480,
                 camera: CameraView | None = None, scene: dict | None = None,
                 with_human: bool = True, overlay: bool = True):
        require_rendering()
        self.replay = Replay(record)
        if scene is None:
            extra_scene = record.extra.get('scene') if isinstance(record.extra, dict) else None
            scene = dict(extra_scene) if isinstance(extra_scene, dict) else {}
        self.width, self.height = int(width), int(height)
        self.overlay = overlay
        # Text about 1/34 of the frame height, smaller if the band would take over a third.
        size = max(10, min(self.height // 34, self.width // 46))
        n_labels = len(self.replay.labels)
        while size > 5 and info_band_height(text_font(size), n_labels) > self.height / 3:
            size -= 1
        self._font = text_font(size)
        self.band_height = info_band_height(self._font, n_labels) if overlay else 0
        self.view_height = self.height - self.band_height
        if self.view_height < 16:
            raise ValueError(f'{width}x{height} leaves no room for the 3D view under the overlay')
        pelvis_xy = None
        if self.replay.person is not None:
            # The human model stands where the person did, its collar at theirs.
            x, y, z, _ = self.replay.person
            pelvis_xy = (x, y)
            scene = {**scene, 'floor_z': z - human_model.collar_height()}
        self.model = build_render_model(self.width, self.view_height, scene, with_human,
                                        pelvis_xy=pelvis_xy, robot=self.replay.robot)
        self.data = mujoco.MjData(self.model)
        if camera is None and self.replay.person is not None:
            # Both people: the robot's base and the person, from their side, at hand height.
            base = self.replay.robot.mount_xyz
            x, y, z, _ = self.replay.person
            camera = CameraView(lookat=((base[0] + x) / 2, (base[1] + y) / 2, z - 0.35),
                                distance=2.9, azimuth=-105.0, elevation=-8.0)
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
        self._renderer = OffscreenRenderer(self.model, self.width, self.view_height)

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
        if r.partner is not None:
            target = r.partner_at(time)
            shown = target is not None
        else:
            target = r.target
            shown = target is not None and (r.record.onset_time is None
                                            or time >= r.record.onset_time)
        d.mocap_pos[self._target_mocap] = np.asarray(target, float) if shown else (0, 0, -50)
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
        band = draw_info_band(self.replay, time, self.width, self.band_height, self._font)
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
