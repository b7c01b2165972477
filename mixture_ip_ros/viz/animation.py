"""The files written for a recorded interaction: an animated GIF played in real time, and a
contact sheet (key frames: onset, commit, movement end, handover; the belief over time below)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from mixture_ip_ros.io.files import write_atomic
from mixture_ip_ros.io.records import InteractionRecord
from mixture_ip_ros.viz.frames import CameraView, InteractionRenderer
from mixture_ip_ros.viz.offscreen import require_rendering
from mixture_ip_ros.viz.overlays import PALETTE, font_size, text_font
from mixture_ip_ros.viz.replay import Replay


def _frame_times(replay: Replay, fps: float) -> np.ndarray:
    t0, t1 = replay.t[0], replay.t[-1]
    return np.arange(t0, t1 + 0.5 / fps, 1.0 / fps).clip(t0, t1)


def _key_times(replay: Replay) -> list[tuple[str, float]]:
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


def _timeline(replay: Replay, width: int, height: int, keys, font) -> Image.Image:
    """p(k | D) per component and the phase over the record's time, events marked."""
    im = Image.new('RGB', (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(im)
    size = font_size(font)
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


def _contact_sheet(frames: list[tuple[str, float, np.ndarray]], replay: Replay,
                   font) -> Image.Image:
    rec = replay.record
    h, w = frames[0][2].shape[:2]
    size = font_size(font)
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
    require_rendering()
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
        font = text_font(max(11, int(height) // 30))
    write_atomic(gif_path, lambda f: frames[0].save(
        f, format='GIF', save_all=True, append_images=frames[1:],
        duration=max(20, int(round(1000 / fps))), loop=0))
    sheet = _contact_sheet(key_frames, r.replay, font)
    write_atomic(sheet_path, lambda f: sheet.save(f, format='PNG'))
    return {'animation': gif_path, 'contact_sheet': sheet_path}
