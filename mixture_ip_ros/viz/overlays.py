"""What frames show besides the scene: the marker colours, and the info band under the 3D view
(p(k | D) per interaction pattern, the time, the estimated phase, whether the robot has
committed, the legend)."""

from __future__ import annotations

import functools

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from mixture_ip_ros.viz.replay import Replay

# Component colours (overlay bars, timeline); the k-th label gets the k-th colour.
PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
           (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
# Markers and paths in the scene, and their legend: the wrist, the robot's hand, the target.
WRIST_RGBA = (0.9, 0.1, 0.1, 1.0)
FLANGE_RGBA = (0.15, 0.35, 0.95, 0.9)
TARGET_RGBA = (0.1, 0.8, 0.2, 0.45)


@functools.lru_cache(maxsize=8)
def text_font(size: int):
    """Pillow's default font at ``size`` pixels (its fixed bitmap font where it cannot scale)."""
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError):     # Pillow without FreeType: the fixed bitmap font
        return ImageFont.load_default()


def font_size(font) -> int:
    """Pixel size of a font from :func:`text_font`."""
    return int(getattr(font, 'size', 11))


def info_band_height(font, n_labels: int) -> int:
    """Pixel height of the info band for ``n_labels`` patterns."""
    size = font_size(font)
    line = int(size * 1.4)
    return 2 * (size // 2) + line * (1 + max(n_labels, 4))


def _status(replay: Replay, time: float) -> tuple[str, bool]:
    """(text, committed) for the band."""
    rec = replay.record
    if rec.commit_time is not None and time >= rec.commit_time:
        frac = (f' at {100 * rec.commit_fraction:.0f} %' if rec.commit_fraction is not None else '')
        return f'robot committed: {rec.chosen_pattern or "?"}{frac}', True
    if rec.onset_time is not None and time < rec.onset_time:
        return 'waiting for the person to move', False
    if rec.end_time is not None and time >= rec.end_time:
        return 'movement over, no commitment', False
    hedging = ((rec.extra or {}).get('interaction') or {}).get('hedged_plans', 0) > 0
    return ('observing, robot hedges' if hedging else 'observing, robot waits'), False


_WHITE, _GREY, _YELLOW, _BAND = (255, 255, 255), (170, 170, 170), (255, 220, 60), (28, 30, 36)


def draw_info_band(replay: Replay, time: float, width: int, height: int, font) -> Image.Image:
    """The info band: p(k | D) bars (left); time, truth, phase, status and legend (right)."""
    rec = replay.record
    im = Image.new('RGB', (width, height), _BAND)
    draw = ImageDraw.Draw(im)
    size = font_size(font)
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
    if replay.partner is not None:
        items.append(("partner's hand", TARGET_RGBA))
    elif rec.target is not None:
        items.append(('target', TARGET_RGBA))
    for text, rgba in items:
        colour = tuple(int(255 * v) for v in rgba[:3])
        d = size * 2 // 3
        draw.ellipse([x, y + (line - d) // 2, x + d, y + (line + d) // 2], fill=colour)
        draw.text((x + d + pad // 2, y), text, font=font, fill=_GREY)
        x += d + pad + int(draw.textlength(text, font=font)) + size
    return im
