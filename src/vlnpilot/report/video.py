"""Episode videos: front view, rear view and floor plan side by side, one video frame per step.

Frame k shows what the pilot saw at step k (as the HTML timeline does), the drone's position and heading on
the plan, and a caption with the step, the state transition and the movement executed. The closing frame
shows the outcome and is held a little longer. `episode.mp4` is H.264 (PyAV); `episode.gif` is
a half-size copy for places that cannot play video (a README, an issue).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from vlnpilot.report.plots import OUTCOME_COLORS, PlanImage, episode_plan
from vlnpilot.report.timeline import Entry, Episode, load_episode

MP4, GIF = "episode.mp4", "episode.gif"
PANEL_H = 360
CAM_W = 480
CAPTION_H = 50
PAD = 8
BG = (245, 246, 248)
INK = (29, 35, 48)
MUTED = (95, 107, 122)
CURSOR = (225, 29, 72)  # the same rose as the HTML page's cursor


def _font(size: int, bold: bool = False) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """DejaVu Sans from matplotlib's own data (present wherever matplotlib is), else Pillow's default font."""
    import matplotlib

    name = "DejaVuSans-Bold.ttf" if bold else "DejaVuSans.ttf"
    try:
        return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts" / "ttf" / name), size)
    except OSError:
        return ImageFont.load_default(size)


def _rgb(hex_color: str) -> tuple[int, int, int]:
    h = hex_color.lstrip("#")
    return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)


def _ceil16(n: int) -> int:
    return (n + 15) // 16 * 16


class _Composer:
    """Lays out one video frame; built once per episode (fonts, the plan resized to the panel height)."""

    def __init__(self, ep: Episode, plan: PlanImage | None):
        self.ep = ep
        self.colors = dict(plan.state_colors) if plan is not None else {}
        self.plan_img: Image.Image | None = None
        self.scale = 1.0
        plan_w = 0
        if plan is not None:
            w, h = plan.size
            self.scale = PANEL_H / h
            plan_w = int(round(w * self.scale))
            self.plan_img = Image.fromarray(plan.rgb).resize((plan_w, PANEL_H), Image.Resampling.LANCZOS)
            self.positions = plan.positions
        content_w = PAD + CAM_W + PAD + CAM_W + PAD + (plan_w + PAD if plan_w else 0)
        self.width = _ceil16(content_w)
        self.height = _ceil16(CAPTION_H + PANEL_H + 2 * PAD)
        self.x0 = (self.width - content_w) // 2
        self.font = _font(17)
        self.bold = _font(18, bold=True)
        self.small = _font(13)
        self.label = _font(13, bold=True)
        self._cam_cache: dict[str, Image.Image] = {}

    def _camera(self, rel: str | None) -> Image.Image:
        if rel is None:
            img = Image.new("RGB", (CAM_W, PANEL_H), (220, 223, 228))
            ImageDraw.Draw(img).text((CAM_W // 2, PANEL_H // 2), "no frame", fill=MUTED, font=self.font, anchor="mm")
            return img
        if rel not in self._cam_cache:
            with Image.open(self.ep.run_dir / rel) as im:
                self._cam_cache[rel] = im.convert("RGB").resize((CAM_W, PANEL_H), Image.Resampling.BILINEAR)
        return self._cam_cache[rel]

    def _tag(self, draw: ImageDraw.ImageDraw, xy: tuple[int, int], text: str, fill: tuple[int, int, int],
             ink: tuple[int, int, int] = (255, 255, 255)) -> int:
        x, y = xy
        w = int(draw.textlength(text, font=self.label)) + 14
        draw.rounded_rectangle((x, y, x + w, y + 22), radius=6, fill=fill)
        draw.text((x + 7, y + 11), text, fill=ink, font=self.label, anchor="lm")
        return x + w

    def frame(self, entry: Entry, total: int) -> np.ndarray:
        img = Image.new("RGB", (self.width, self.height), BG)
        draw = ImageDraw.Draw(img)
        # caption: step, state transition, movement; the outcome on the closing frame
        y = PAD + CAPTION_H // 2 - 4
        x = self.x0 + PAD
        if entry.step is not None:
            head = f"Step {entry.step}/{total}"
        else:
            head = "End"
        draw.text((x, y), head, fill=INK, font=self.bold, anchor="lm")
        x += int(draw.textlength(head, font=self.bold)) + 14
        state = entry.state or "?"
        x = self._tag(draw, (x, y - 11), state, _rgb(self.colors.get(state, "#8a93a0"))) + 6
        if entry.step is not None:
            if entry.next_state and entry.next_state != entry.state:
                draw.text((x, y), "→", fill=MUTED, font=self.font, anchor="lm")
                x += 24
                nxt = entry.next_state
                x = self._tag(draw, (x, y - 11), nxt, _rgb(self.colors.get(nxt, "#8a93a0"))) + 6
            move = self._move_text(entry)
            draw.text((x + 10, y), move, fill=INK, font=self.font, anchor="lm")
        else:
            r = self.ep.result
            outcome = self.ep.shown_outcome
            x = self._tag(draw, (x + 4, y - 11), outcome.replace("_", " "),
                          _rgb(OUTCOME_COLORS.get(outcome, "#5f6b7a"))) + 10
            draw.text((x, y), str(r.get("reason") or "")[:110], fill=MUTED, font=self.font, anchor="lm")
        # panels
        top = PAD + CAPTION_H
        x = self.x0 + PAD
        for view, label in (("front", "front · seen by the pilot" if entry.step is not None else "front"),
                            ("rear", "rear")):
            img.paste(self._camera(entry.frames.get(view)), (x, top))
            self._tag(draw, (x + 6, top + 6), label, (20, 24, 32))
            x += CAM_W + PAD
        if self.plan_img is not None:
            img.paste(self.plan_img, (x, top))
            pos = self.positions[entry.index] if entry.index < len(self.positions) else None
            if pos is not None:
                self._cursor(draw, x + pos[0] * self.scale, top + pos[1] * self.scale,
                             float((entry.pose or {}).get("yaw_deg", 0.0)))
        if entry.collided:
            draw.rectangle((self.x0 + PAD - 3, top - 3, self.x0 + PAD + 2 * CAM_W + PAD + 2, top + PANEL_H + 2),
                           outline=_rgb(OUTCOME_COLORS["collision"]), width=3)
        return np.asarray(img)

    def _move_text(self, entry: Entry) -> str:
        from vlnpilot.core.commands import COMMANDS

        if not entry.executed:
            return "no valid decision: episode stopped"
        cmd = COMMANDS.get(entry.executed)
        text = f"{entry.executed}: {cmd.description if cmd else ''}"
        if entry.proposed and entry.proposed != entry.executed:
            text += f" (proposed {entry.proposed})"
        if entry.decision is None:
            text += " · no valid decision"
        elif entry.failures:
            text += f" · {len(entry.failures)} re-ask{'s' if len(entry.failures) > 1 else ''}"
        for item in entry.interventions:
            if isinstance(item, dict) and item.get("source"):
                text += f" · {str(item['source']).replace('_', ' ')}"
            else:
                text += " · safety"
        if entry.collided:
            text += " · COLLISION"
        return text

    @staticmethod
    def _cursor(draw: ImageDraw.ImageDraw, cx: float, cy: float, yaw_deg: float) -> None:
        r = 10
        a = math.radians(yaw_deg)
        tip = (cx + 24 * math.cos(a), cy - 24 * math.sin(a))
        draw.line((cx, cy, *tip), fill=(255, 255, 255), width=7)
        draw.line((cx, cy, *tip), fill=CURSOR, width=3)
        draw.ellipse((cx - r - 2, cy - r - 2, cx + r + 2, cy + r + 2), outline=(255, 255, 255), width=3)
        draw.ellipse((cx - r, cy - r, cx + r, cy + r), outline=CURSOR, width=3)


def episode_frames(ep: Episode, plan: PlanImage | None = None) -> list[np.ndarray]:
    """One composed RGB frame per timeline entry (steps, then the end)."""
    if plan is None:
        plan = episode_plan(ep, width_px=int(PANEL_H * 2.6))
    comp = _Composer(ep, plan)
    total = len(ep.entries) - 1
    return [comp.frame(e, total) for e in ep.entries]


def _write_gif(frames: list[np.ndarray], path: Path, *, fps: float, width: int, hold: int, colors: int = 96) -> Path:
    h, w = frames[0].shape[:2]
    size = (width, int(round(h * width / w)))
    small = [Image.fromarray(f).resize(size, Image.Resampling.LANCZOS) for f in frames]
    # one palette for the whole clip (from a few frames) keeps colours stable and the file small
    sample = Image.new("RGB", (size[0], size[1] * min(4, len(small))))
    for i, im in enumerate(small[:: max(1, len(small) // 4)][:4]):
        sample.paste(im, (0, i * size[1]))
    palette = sample.quantize(colors=colors, method=Image.Quantize.MEDIANCUT)
    quant = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in small]
    durations = [int(1000 / fps)] * len(quant)
    durations[-1] *= hold
    quant[0].save(path, save_all=True, append_images=quant[1:], duration=durations, loop=0, optimize=False,
                  disposal=1)
    return path


def _write_mp4(frames: list[np.ndarray], path: Path, *, fps: float, hold: int) -> Path:
    """H.264 (yuv420p, fast start) with PyAV, the project's one FFmpeg stack; written aside, then moved."""
    import av

    rate = Fraction(fps).limit_denominator(1000)
    with (_written_through(path.with_name(f".{path.name}.tmp.mp4"), path) as tmp,  # the format from the suffix
          av.open(str(tmp), mode="w", options={"movflags": "+faststart"}) as container):
        stream = container.add_stream("libx264", rate=rate, options={"preset": "veryfast", "crf": "20"})
        stream.height, stream.width = frames[0].shape[:2]
        stream.pix_fmt = "yuv420p"
        for image in [*frames, *[frames[-1]] * max(0, hold - 1)]:
            container.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        container.mux(stream.encode(None))  # flush the encoder's delayed frames
    return path


def write_episode_video(run_dir: str | Path, *, fps: float = 2.0, gif: bool = True, gif_width: int = 720,
                        hold_last: int = 4, episode: Episode | None = None) -> tuple[Path, Path | None]:
    """Write `episode.mp4` (and `episode.gif` unless `gif=False`) into a run directory; returns their paths."""
    run_dir = Path(run_dir)
    ep = episode or load_episode(run_dir)
    frames = episode_frames(ep)
    mp4 = _write_mp4(frames, run_dir / MP4, fps=fps, hold=hold_last)
    gif_path = None
    if gif:
        with _written_through(run_dir / f".{GIF}.tmp.gif", run_dir / GIF) as tmp:
            _write_gif(frames, tmp, fps=fps, width=gif_width, hold=hold_last)
        gif_path = run_dir / GIF
    return mp4, gif_path


@contextlib.contextmanager
def _written_through(tmp: Path, final: Path) -> Iterator[Path]:
    """Write `tmp`, then move it onto `final`; whatever stops the writing (Ctrl-C, SIGTERM, a full disk)
    leaves neither a half file nor the temporary one."""
    try:
        yield tmp
        tmp.replace(final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
