"""``animation.gif``: the robot seen from the side over time, one panel per run, the same time in every panel.

Each panel draws what :func:`mwip_ros.core.plants.markers.robot_pose` says (the one geometry of the
robot): the ground, the wheel (a circle and a spoke that shows its rotation), the body (a rod
from the axle to twice the centre of gravity's distance) and a dashed upright reference through
the axle, so the tilt theta_b reads directly.  The view follows each robot horizontally (a run
drives metres while the body is under one metre tall: a view holding the whole run would shrink
the robot to a few pixels); ground ticks every :data:`TICK` m move past to show the motion, and
a readout gives the wheel's x and theta_b.  Both axes have one scale, so the rod's drawn angle
is theta_b.  Frame k shows every run at t_k = t_start + k / ``fps`` (each run's latest sample at
or before t_k, see :func:`frame_times`; the last frame is the latest run's end, held :data:`HOLD_END_MS`)
and the GIF plays at ``fps``: real time (a run longer than :data:`MAX_FRAMES` frames gets a lower
``fps``).  A run that fell (|theta_b| beyond ``fall_angle`` in its table, the plant's record of a fall
in its ``record``, or its ``fallen`` flag, see :func:`fall_time`) is
titled "FELL at t = ..." in :data:`FELL_COLOUR` from then on; a run that ended before the others
holds its last pose.

Drawn with Pillow at twice the size and reduced (antialiased edges), text at the final size,
every frame mapped onto one fixed palette (the drawing's colours and their blends with the
background): a few milliseconds a frame, exact colours, a small file.  No ROS here.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

from mwip_ros.core.closed_loop import metrics
from mwip_ros.core.plants.markers import robot_pose
from mwip_ros.core.plants.model import PhysicalParams

__all__ = ["FPS", "MAX_FRAMES", "MAX_SPAN_S", "MAX_FRAME_MS", "frame_count", "refusal", "TICK", "HOLD_END_MS",
           "PANEL_SIZE", "HEADER", "ROD_COLOUR", "SPOKE_COLOUR", "FELL_COLOUR", "default_nominal", "fall_time",
           "frame_times", "write_gif"]

FPS = 20.0            # frames per second of simulated time and of playback (50 ms a frame: exact in a GIF)
MAX_FRAMES = 1200     # a longer animation gets fewer frames per second (a 10 min run: 2 fps), still in real time
TICK = 0.25           # [m] between ground ticks
HOLD_END_MS = 1500    # [ms] the last frame is shown before the GIF loops
MAX_FRAME_MS = 655_350   # [ms] a GIF frame's longest delay (65535 hundredths of a second)
MAX_SPAN_S = (MAX_FRAMES - 1) * MAX_FRAME_MS / 1000.0   # [s] the longest span played in real time (9 days)
MAX_FRAME_TIMES = 1_000_000   # frame_times refuses more (write_gif never asks for more than MAX_FRAMES)
PANEL_SIZE = (280, 220)   # [px] of one run's panel
HEADER = 24           # [px] above the panels: the time readout
_SS = 2               # drawn at _SS times the size, then reduced: antialiased edges
_TOP = 36             # [px] of a panel above the scene: its title and readout

BACKGROUND = (255, 255, 255)
ROD_COLOUR = (31, 87, 200)        # the body
SPOKE_COLOUR = (240, 140, 0)      # the wheel's spoke
FELL_COLOUR = (205, 30, 30)       # the title of a fallen run
WHEEL_EDGE = (30, 30, 30)
WHEEL_FILL = (205, 205, 205)
GROUND = (90, 90, 90)
REFERENCE = (160, 160, 160)       # the upright reference and the panels' separator
TEXT = (0, 0, 0)
_COLOURS = (ROD_COLOUR, SPOKE_COLOUR, FELL_COLOUR, WHEEL_EDGE, WHEEL_FILL, GROUND, REFERENCE, TEXT)
_LEVELS = 24          # blends of each colour with the background in the palette


def default_nominal() -> PhysicalParams:
    """The nominal model of the parameter schema's defaults (what ``robot_markers`` draws without a file).

    Returns
    -------
    PhysicalParams
    """
    from mwip_ros import params as P
    return P.physical(P.defaults_for("robot_markers"), "nominal")


def fall_time(run, fall_angle: float) -> Optional[float]:
    """When ``run`` fell, as its trajectory table tells.

    Parameters
    ----------
    run : Trajectory
        A run of the trajectory table (columns ``t``, ``theta_b``; attribute ``fallen``).
    fall_angle : float
        |theta_b| beyond this is a fall [rad].

    Returns
    -------
    float or None
        The first t with |theta_b| > ``fall_angle``; else the fall the run's ``record`` holds (a bag's
        plant log); else the last t if the run's ``fallen`` flag is set; else None.
    """
    t = np.asarray(run["t"], dtype=float)
    fell = metrics.fall_time(t, run["theta_b"], fall_angle)
    if fell is not None:
        return fell
    recorded = (getattr(run, "record", None) or {}).get("t_fall")   # the plant's own record (a bag's log)
    if recorded is not None:
        return float(recorded)
    return float(t[-1]) if getattr(run, "fallen", False) and len(t) else None


def frame_times(runs: Sequence, fps: float = FPS) -> np.ndarray:
    """The times of the frames: from the earliest start to the latest end of the runs, 1 / ``fps`` apart.

    Parameters
    ----------
    runs : sequence of Trajectory
    fps : float
        Frames per second of simulated time (> 0).

    Returns
    -------
    numpy.ndarray
        t_k = t_start + k / fps for k = 0 .. floor((t_end - t_start) fps), then t_end itself when it is
        not on that grid: the last frame shows how the runs ended (a fall at t = 0.48 s with frames every
        0.05 s would otherwise never be shown).

    Raises
    ------
    ValueError
        ``fps`` not > 0, times that are not finite, or more than :data:`MAX_FRAME_TIMES` frames (counted
        before any is allocated: :func:`write_gif` lowers ``fps`` to :data:`MAX_FRAMES` first).
    """
    if not fps > 0 or not math.isfinite(fps):
        raise ValueError(f"fps must be > 0, got {fps!r}")
    t0, t1 = _span(runs)
    n = frame_count(t0, t1, fps)
    if n > MAX_FRAME_TIMES:
        raise ValueError(f"{n:,.0f} frames of {1 / fps:g} s over t = {t0:g} .. {t1:g} s: more than "
                         f"{MAX_FRAME_TIMES:,}")
    times = t0 + np.arange(int(n)) / fps
    return np.append(times, t1) if t1 - times[-1] > 1e-6 else times


def frame_count(t0: float, t1: float, fps: float) -> float:
    """How many frames 1 / ``fps`` apart span [t0, t1] (a float: it may be astronomically many)."""
    return math.floor((t1 - t0) * fps + 1e-9) + 1.0


def refusal(runs: Sequence) -> Optional[str]:
    """Why the runs cannot be animated in real time, in one line, or None when they can: times that are not
    finite, or a span longer than :data:`MAX_FRAMES` frames of a GIF's longest frame (:data:`MAX_SPAN_S`)."""
    if not runs:
        return "no runs to animate"
    try:
        t0, t1 = _span(runs)
    except (ValueError, IndexError):
        return "a run has no samples"
    if not (math.isfinite(t0) and math.isfinite(t1)):
        return f"the runs' times are not finite (t = {t0!r} .. {t1!r} s)"
    if t1 - t0 > MAX_SPAN_S:
        return (f"the runs span {t1 - t0:g} s: animation.gif plays in real time, at most {MAX_SPAN_S:,.0f} s "
                f"({MAX_FRAMES} frames of at most {MAX_FRAME_MS / 1000:g} s, a GIF's longest)")
    return None


def _span(runs: Sequence) -> Tuple[float, float]:
    """(the earliest start, the latest end) of the runs."""
    return min(float(r["t"][0]) for r in runs), max(float(r["t"][-1]) for r in runs)


def _palette() -> List[int]:
    """768 values: the background, each colour blended with it in :data:`_LEVELS` steps, greys."""
    bg = np.array(BACKGROUND, dtype=float)
    entries = [BACKGROUND]
    for c in _COLOURS:
        for a in np.linspace(1.0, 0.0, _LEVELS, endpoint=False):
            entries.append(tuple(int(round(v)) for v in a * np.array(c, dtype=float) + (1 - a) * bg))
    entries += [(g, g, g) for g in range(0, 256, 16)]
    entries = list(dict.fromkeys(entries))[:256]
    entries += [entries[-1]] * (256 - len(entries))
    return [v for e in entries for v in e]


def _font(size: int):
    from PIL import ImageFont
    try:   # a monospaced face keeps the readouts still; matplotlib ships one
        from matplotlib import font_manager
        return ImageFont.truetype(font_manager.findfont("DejaVu Sans Mono", fallback_to_default=False), size)
    except Exception:  # noqa: BLE001 - any missing font: Pillow's own
        return ImageFont.load_default(size)


class _Panel:
    """One run's panel: its samples, where its fall is, and how to draw it at a time."""

    def __init__(self, run, nominal: PhysicalParams, fall_angle: float):
        self.run, self.nominal = run, nominal
        t, w, b = (np.asarray(run[c], dtype=float) for c in ("t", "theta_w", "theta_b"))
        ok = np.isfinite(t) & np.isfinite(w) & np.isfinite(b)    # a row without a state draws nothing
        self.t, self.theta_w, self.theta_b = t[ok], w[ok], b[ok]
        self.fell = fall_time(run, fall_angle)

    def pose(self, t: float):
        """The pose of the latest sample at or before ``t`` (the first before the run starts)."""
        if not len(self.t):
            return robot_pose(self.nominal, (math.nan, math.nan))
        i = max(0, int(np.searchsorted(self.t, t + 1e-9, side="right")) - 1)
        return robot_pose(self.nominal, (self.theta_w[i], self.theta_b[i]))

    def title(self, t: float) -> Tuple[str, tuple]:
        if self.fell is not None and t >= self.fell - 1e-9:
            return f"{self.run.label}: FELL at t = {self.fell:.3f} s", FELL_COLOUR
        if not len(self.t):
            return f"{self.run.label} (no states)", TEXT
        if t > self.t[-1] + 1e-9:
            return f"{self.run.label} (ended at t = {self.t[-1]:.2f} s)", TEXT
        return str(self.run.label), TEXT

    def draw(self, img, pose) -> None:
        """Draw the scene of ``pose`` (:meth:`pose`) onto ``img`` (one panel, :data:`_SS` times the final size)."""
        from PIL import ImageDraw

        d = ImageDraw.Draw(img)
        w, h = img.size
        r, length = pose.wheel_radius, pose.body_length
        ground = h - 0.12 * (h - _TOP * _SS)
        scale = 0.8 * (h - _TOP * _SS) / (r + length)   # [px/m], the same on both axes
        robot = math.isfinite(pose.wheel_center[0]) and math.isfinite(pose.theta_b)   # else: a run without states
        cx = pose.wheel_center[0] if robot else 0.0

        def px(p):   # world (x, y, z) -> pixel, the view centred on the wheel
            return (w / 2 + (p[0] - cx) * scale, ground - p[2] * scale)

        d.line([(0, ground), (w, ground)], fill=GROUND, width=2 * _SS)
        half = w / 2 / scale
        for k in range(math.ceil((cx - half) / TICK), math.floor((cx + half) / TICK) + 1):
            x = w / 2 + (k * TICK - cx) * scale
            d.line([(x, ground), (x, ground + 6 * _SS)], fill=GROUND, width=_SS)
        if not robot:
            return
        (ax, ay), top = px(pose.wheel_center), ground - (r + length) * scale
        dash = 5 * _SS
        for y in np.arange(ay, top, -2 * dash):
            d.line([(ax, y), (ax, max(top, y - dash))], fill=REFERENCE, width=_SS)
        rp = r * scale
        d.ellipse([ax - rp, ay - rp, ax + rp, ay + rp], fill=WHEEL_FILL, outline=WHEEL_EDGE, width=2 * _SS)
        d.line([(ax, ay), px(pose.spoke_end)], fill=SPOKE_COLOUR, width=3 * _SS)
        d.line([(ax, ay), px(pose.body_top)], fill=ROD_COLOUR, width=4 * _SS)

    def text(self, d, x0: int, t: float, pose, fonts) -> None:
        """Title at ``t`` and readout of ``pose`` at the final size; the panel's left edge is ``x0``."""
        title, colour = self.title(t)
        font = fonts[1] if d.textlength(title, font=fonts[1]) <= PANEL_SIZE[0] - 8 else fonts[0]
        while len(title) > 4 and d.textlength(title, font=font) > PANEL_SIZE[0] - 8:   # a long label: its end shows
            title = "..." + title[4:]
        d.text((x0 + PANEL_SIZE[0] / 2, HEADER + 2), title, fill=colour, font=font, anchor="mt")
        readout = f"x {pose.wheel_center[0]:+7.2f} m  theta_b {math.degrees(pose.theta_b):+6.2f} deg"
        d.text((x0 + 6, HEADER + 20), readout, fill=TEXT, font=fonts[0], anchor="lt")


def write_gif(runs: Sequence, path, nominal: Optional[PhysicalParams] = None, fps: float = FPS,
              fall_angle: float = math.inf) -> int:
    """Write the runs side by side as an animated GIF.

    Parameters
    ----------
    runs : sequence of Trajectory
        One panel each, left to right, titled with its ``label``; the columns ``t``, ``theta_w``
        and ``theta_b`` are drawn.
    path : str or Path
        The GIF to write.
    nominal : PhysicalParams, optional
        Sizes the robot (wheel radius r, body 2 l); default :func:`default_nominal`.
    fps : float
        Frames per second of simulated time; the GIF plays at this rate (real time).  Lowered so
        that there are at most :data:`MAX_FRAMES` frames (memory and file size stay bounded).
    fall_angle : float
        |theta_b| beyond this marks a run as fallen [rad] (its ``fallen`` flag marks it too).

    Returns
    -------
    int
        The number of frames written: ``len(frame_times(runs, fps))``.  The image is
        ``len(runs) * PANEL_SIZE[0]`` by ``HEADER + PANEL_SIZE[1]`` pixels.  Consecutive frames
        always differ (the time readout), so the GIF holds every one.
    """
    from PIL import Image, ImageDraw

    if not fps > 0 or not math.isfinite(fps):
        raise ValueError(f"fps must be > 0, got {fps!r}")
    why = refusal(runs)
    if why:
        raise ValueError(why)
    nominal = nominal or default_nominal()
    t0, t1 = _span(runs)
    if frame_count(t0, t1, fps) + 1 > MAX_FRAMES:   # a long run: fewer frames per second, still in real time
        fps = (MAX_FRAMES - 2) / (t1 - t0)          # counted before any frame time is allocated
    times = frame_times(runs, fps)
    panels = [_Panel(run, nominal, fall_angle) for run in runs]
    pw, ph = PANEL_SIZE
    size = (pw * len(panels), HEADER + ph)
    fonts = (_font(11), _font(13), _font(15))
    pal = Image.new("P", (1, 1))
    pal.putpalette(_palette())
    frames = []
    for t in times:
        frame = Image.new("RGB", size, BACKGROUND)
        poses = [p.pose(float(t)) for p in panels]
        for j, (p, pose) in enumerate(zip(panels, poses)):
            scene = Image.new("RGB", (pw * _SS, ph * _SS), BACKGROUND)
            p.draw(scene, pose)
            frame.paste(scene.reduce(_SS), (j * pw, HEADER))
        d = ImageDraw.Draw(frame)
        for j, (p, pose) in enumerate(zip(panels, poses)):
            p.text(d, j * pw, float(t), pose, fonts)
            if j:
                d.line([(j * pw, HEADER), (j * pw, size[1])], fill=REFERENCE, width=1)
        d.text((size[0] / 2, 3), f"t = {t:6.2f} s", fill=TEXT, font=fonts[2], anchor="mt")
        frames.append(frame.quantize(palette=pal, dither=Image.Dither.NONE))
    step = min(MAX_FRAME_MS, max(10, int(round(1000 / fps))))
    durations = [step] * len(frames)
    # the end (a fall, the last pose) stays readable before the loop
    durations[-1] = min(MAX_FRAME_MS, max(step, HOLD_END_MS))
    frames[0].save(Path(path), save_all=True, append_images=frames[1:], duration=durations, loop=0)
    return len(frames)
