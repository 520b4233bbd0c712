"""``mwip_sim --render FILE``: the MuJoCo robot drawn in 3D as it runs (``plant_sim.backend: mujoco``).

The frames are MuJoCo's own renderer looking at the plant's model (:func:`mwip_ros.core.plants.mujoco_plant.mjcf`: the
same bodies, joints, ground, slope and steps that the physics integrates) with a few shapes added for the eye only
(:func:`film_model`): the body as a box from the axle to twice its centre of gravity's height (where
:func:`mwip_ros.core.plants.markers.robot_pose` draws the rod of the 2D animation), a spoke across each wheel so its
rotation shows, an IMU marker, and a checkered ground whose squares are :data:`SQUARE` m.  The added geoms collide
with nothing and the frames copy the plant's positions into a model of their own, so drawing never changes the
simulation: a run with ``--render`` is the run without it, to the bit.

A ``.gif`` is the run at :data:`FPS` frames a second of simulated time, played in real time; a ``.png`` is a
contact sheet of :data:`SHEET` frames evenly spread over the run, each with its time.  The camera follows the
axle from behind and to the left, at :data:`DISTANCE` m.  MuJoCo draws through OpenGL: with no display,
``MUJOCO_GL=egl`` (a GPU or Mesa's EGL) or ``osmesa``; where none works the option is refused before the run
(:func:`gl_refusal`).
"""
from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

__all__ = ["FPS", "SHEET", "SIZE", "SQUARE", "DISTANCE", "TRAIL_S", "Film", "Filmer", "UrdfFilm", "film_model",
           "urdf_model", "gl_refusal", "suffix_refusal"]

FPS = 20.0                # frames per simulated second in a .gif (50 ms a frame: exact in a GIF), played in real time
SHEET = 6                 # frames on a .png contact sheet (3 x 2)
SIZE = (480, 360)         # one frame [px]
SQUARE = 0.5              # the ground's checker squares [m]
DISTANCE = 5.0            # the camera from the axle [m]
MAX_GIF_FRAMES = 1200     # a longer run is drawn at a lower rate (still in real time)
_BODY_RGBA = (0.85, 0.45, 0.1, 1.0)
_SPOKE_RGBA = (0.95, 0.95, 0.95, 1.0)
_TRAIL_RGBA = (0.1, 0.35, 0.8, 1.0)
TRAIL_S = 0.1             # the drawn path of the axle: a point every TRAIL_S of simulated time


def _mujoco():
    from mwip_ros.core.plants.mujoco_plant import mujoco_module   # headless: EGL (mwip_ros.optional.required)
    return mujoco_module()


def suffix_refusal(path: Path) -> Optional[str]:
    """Why ``--render`` cannot write ``path`` (it must end in .gif or .png), or None."""
    if path.suffix.lower() not in (".gif", ".png"):
        return f"--render {path}: the file must end in .gif (the run, animated) or .png (a sheet of {SHEET} frames)"
    return None


@functools.lru_cache(maxsize=None)
def gl_refusal() -> Optional[str]:
    """Why MuJoCo cannot draw here (no OpenGL context), one line, or None: tried once with a one-geom model (MuJoCo
    picks its GL platform when it is imported; a second try after a failed one can abort the process)."""
    try:
        mj = _mujoco()
        m = mj.MjModel.from_xml_string('<mujoco><worldbody><geom type="sphere" size="1"/></worldbody></mujoco>')
        r = mj.Renderer(m, 8, 8)
        r.update_scene(mj.MjData(m))
        r.render()
        r.close()
    except Exception as exc:   # noqa: BLE001 - whatever the GL platform raises, it is the reason
        from mujoco.rendering.classic import gl_context
        gl = getattr(getattr(gl_context, "GLContext", None), "__module__", "none").rsplit(".", 1)[-1]
        return (f"--render: MuJoCo cannot draw here (its GL platform: {gl}; {type(exc).__name__}: "
                f"{str(exc).splitlines()[0] if str(exc) else ''}); try MUJOCO_GL=egl or MUJOCO_GL=osmesa")
    return None


def film_model(cfg):
    """The plant's MJCF model (:func:`~mwip_ros.core.plants.mujoco_plant.mjcf` of the
    :class:`~mwip_ros.core.plants.plant.PlantConfig` ``cfg``) with the shapes of the module docstring added: the same
    joints in the same order, so a plant's ``qpos`` places it."""
    from mwip_ros.core.plants.mujoco_plant import MujocoConfig, mjcf
    mj = _mujoco()
    spec = mj.MjSpec.from_string(mjcf(cfg))
    p, mc = cfg.actual, cfg.mujoco or MujocoConfig()
    _stage(spec, mj)
    for g in spec.geoms:
        if g.name.startswith("step_"):
            g.rgba = [0.55, 0.5, 0.35, 1.0]
    quiet = dict(contype=0, conaffinity=0, group=1)
    body = spec.body("body")
    body.add_geom(type=mj.mjtGeom.mjGEOM_BOX, size=[0.06, 0.3 * mc.track_width, p.l], pos=[0.0, 0.0, p.l],
                  rgba=list(_BODY_RGBA), **quiet)
    if cfg.raw is not None:
        body.add_geom(type=mj.mjtGeom.mjGEOM_BOX, size=[0.07, 0.05, 0.02], pos=[0.0, 0.0, cfg.raw.offset],
                      rgba=[0.1, 0.6, 0.9, 1.0], **quiet)
    for side in ("left", "right"):
        wheel = spec.body(f"wheel_{side}")
        for a in (0.0, math.pi / 2):   # two bars across the disc, a little wider than it, turning with it
            wheel.add_geom(type=mj.mjtGeom.mjGEOM_BOX, size=[0.9 * p.r, 0.12 * p.r, 0.06 * p.r],
                           quat=[math.cos(a / 2), 0.0, math.sin(a / 2), 0.0], rgba=list(_SPOKE_RGBA), **quiet)
    return _compiled(spec)


def _stage(spec, mj) -> None:
    """The ground's checker and the sky (``spec`` has a geom named ground or gets one)."""
    tex = spec.add_texture(name="checker", type=mj.mjtTexture.mjTEXTURE_2D, builtin=mj.mjtBuiltin.mjBUILTIN_CHECKER,
                           rgb1=[0.78, 0.8, 0.82], rgb2=[0.62, 0.65, 0.68], width=64, height=64)
    spec.add_material(name="ground", textures=["", tex.name], texrepeat=[1.0 / (2 * SQUARE)] * 2, texuniform=True)
    spec.add_texture(name="sky", type=mj.mjtTexture.mjTEXTURE_SKYBOX, builtin=mj.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.75, 0.85, 0.95], rgb2=[1.0, 1.0, 1.0], width=64, height=64)
    if not any(g.name == "ground" for g in spec.geoms):
        spec.worldbody.add_geom(name="ground", type=mj.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0])
    for g in spec.geoms:
        if g.name == "ground":
            g.material = "ground"
            g.size = [0.0, 0.0, 1.0]


def _compiled(spec):
    """The lights, then the model, able to draw frames of :data:`SIZE`."""
    spec.worldbody.add_light(pos=[0.0, 0.0, 6.0], dir=[0.3, 0.2, -1.0], diffuse=[0.5, 0.5, 0.5])
    spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    model = spec.compile()
    model.vis.global_.offwidth, model.vis.global_.offheight = max(SIZE[0], 640), max(SIZE[1], 480)
    return model


def urdf_model(urdf_text: str):
    """The robot of a URDF (``robot_description``: :func:`mwip_ros.core.mobile_base.urdf.urdf`) as MuJoCo reads it, its
    visuals kept, ``base_link`` free to be placed (a free joint) and a ground: drawn by :class:`UrdfFilm` from a frame
    tree."""
    mj = _mujoco()
    text = urdf_text
    head = '<mujoco><compiler discardvisual="false" fusestatic="false"/></mujoco>'
    at = text.index(">", text.index("<robot")) + 1
    spec = mj.MjSpec.from_string(text[:at] + head + text[at:])
    from mwip_ros.core.mobile_base.urdf import BASE_LINK
    spec.body(BASE_LINK).add_freejoint()
    for g in spec.geoms:   # a viewer draws a link's visuals, not its collision shapes (group 3: hidden)
        if g.contype:
            g.group = 3
    _stage(spec, mj)
    return _compiled(spec)


class Film:
    """Frames of a moving robot at :attr:`times` (a .gif's in real time, or a .png sheet's :data:`SHEET`), the axle's
    path drawn on the ground, written by :meth:`write`; subclasses place the model (module docstring)."""

    def __init__(self, model, duration_s: float, path: Path):
        mj = self._mj = _mujoco()
        self.path, self.sheet = Path(path), Path(path).suffix.lower() == ".png"
        self.model, self.data = model, mj.MjData(model)
        self.renderer = mj.Renderer(self.model, SIZE[1], SIZE[0])
        self.camera = mj.MjvCamera()
        self.camera.distance, self.camera.azimuth, self.camera.elevation = DISTANCE, 135.0, -28.0
        self.fps = FPS if self.sheet else min(FPS, MAX_GIF_FRAMES / max(duration_s, 1e-9))
        self.times = (list(np.linspace(0.0, duration_s, SHEET)) if self.sheet
                      else list(np.arange(0.0, duration_s + 1e-9, 1.0 / self.fps)))
        self.frames: List[Tuple[float, np.ndarray]] = []
        self._next = 0
        self.trail: List[Tuple[float, float, float]] = []   # the axle's path so far, a point every TRAIL_S
        self._trail_t = -math.inf

    def due(self, t: float, ground) -> bool:
        """Note the axle's point on the ground ``ground`` (x, y, z) for the path; True when a frame is due at ``t``."""
        if t >= self._trail_t + TRAIL_S - 1e-9:
            self.trail.append((float(ground[0]), float(ground[1]), float(ground[2]) + 0.005))
            self._trail_t = t
        if self._next >= len(self.times) or t + 1e-9 < self.times[self._next]:
            return False
        while self._next < len(self.times) and self.times[self._next] <= t + 1e-9:
            self._next += 1
        return True

    def shoot(self, t: float, qpos) -> None:
        """Draw the model at the generalized position ``qpos`` (its free joint first: the axle), time ``t``."""
        mj, d = self._mj, self.data
        d.qpos[:] = qpos
        d.qvel[:] = 0.0
        mj.mj_kinematics(self.model, d)
        self.camera.lookat[:] = [d.qpos[0], d.qpos[1], d.qpos[2] + 0.4]
        self.renderer.update_scene(d, camera=self.camera)
        self._draw_trail()
        self.frames.append((t, self.renderer.render().copy()))

    def _draw_trail(self) -> None:
        """The axle's path so far as a line on the ground (added to the frame's scene, not to the model)."""
        mj, scn = self._mj, self.renderer.scene
        for a, b in zip(self.trail, self.trail[1:]):
            if scn.ngeom >= scn.maxgeom:
                return
            g = scn.geoms[scn.ngeom]
            mj.mjv_initGeom(g, mj.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.zeros(9),
                            np.array(_TRAIL_RGBA, dtype=np.float32))
            mj.mjv_connector(g, mj.mjtGeom.mjGEOM_CAPSULE, 0.015, np.array(a), np.array(b))
            scn.ngeom += 1

    def write(self, title: str = "") -> Path:
        """Save the frames (a .gif in real time, or a .png sheet with each frame's time); returns the path."""
        from PIL import Image, ImageDraw
        if not self.frames:
            raise ValueError("no frame was drawn (the run ended before t = 0 was reached)")
        images = []
        for t, rgb in self.frames:
            im = Image.fromarray(rgb)
            ImageDraw.Draw(im).text((8, 6), f"{title}  t = {t:5.2f} s".strip(), fill=(20, 20, 20))
            images.append(im)
        if self.sheet:
            cols = 3
            rows = math.ceil(len(images) / cols)
            sheet = Image.new("RGB", (cols * SIZE[0], rows * SIZE[1]), (255, 255, 255))
            for i, im in enumerate(images):
                sheet.paste(im, ((i % cols) * SIZE[0], (i // cols) * SIZE[1]))
            sheet.save(self.path)
        else:
            pal = [im.convert("P", palette=Image.Palette.ADAPTIVE, colors=128) for im in images]
            pal[0].save(self.path, save_all=True, append_images=pal[1:], duration=int(round(1000 / self.fps)),
                        loop=0, optimize=False)
        self.renderer.close()
        return self.path


class Filmer(Film):
    """Frames of a MuJoCo plant as the loop runs: call it with the plant every period (``simulate(on_period=...)``)."""

    def __init__(self, cfg, duration_s: float, path: Path):
        super().__init__(film_model(cfg), duration_s, path)

    def __call__(self, plant) -> None:
        q = plant.data.qpos
        if self.due(plant.t, (q[0], q[1], q[2] - plant.cfg.actual.r)):
            self.shoot(plant.t, q)


class UrdfFilm(Film):
    """Frames of the URDF placed by a frame tree, as a 3D viewer of ``robot_description`` and ``/tf`` draws it
    (Foxglove's 3D panel, RViz): call :meth:`see` with each tree
    (:func:`mwip_ros.core.mobile_base.urdf.frame_transforms`, or the transforms a live view sent)."""

    def __init__(self, urdf_text: str, duration_s: float, path: Path):
        from mwip_ros.core.mobile_base.urdf import WHEEL_JOINTS
        super().__init__(urdf_model(urdf_text), duration_s, path)
        mj = self._mj
        self._wheels = [(mj.mj_name2id(self.model, mj.mjtObj.mjOBJ_JOINT, name), name) for name in WHEEL_JOINTS]

    def see(self, t: float, transforms) -> None:
        from mwip_ros.core.mobile_base.urdf import BASE_LINK, ODOM_FRAME, WHEEL_LINKS
        by_child = {tf.child: tf for tf in transforms}
        base = by_child[BASE_LINK]
        assert base.parent == ODOM_FRAME, base
        x, y, z = base.translation
        if not self.due(t, (x, y, 0.0)):
            return
        qx, qy, qz, qw = base.rotation
        q = self.data.qpos.copy()
        q[:7] = [x, y, z, qw, qx, qy, qz]
        for (jid, _), link in zip(self._wheels, WHEEL_LINKS):   # a wheel's turn about its axis (y) in its tree
            r = by_child[link].rotation
            q[self.model.jnt_qposadr[jid]] = 2.0 * math.atan2(r[1], r[3])
        self.shoot(t, q)


def film_bag(bag, path: Path) -> Tuple[Path, int]:
    """Draw a bag's robot as a 3D viewer of its ``robot_description`` and frames shows it (Foxglove's 3D panel, RViz):
    the URDF placed by robot_state's ``odom`` and ``wheel_joint_states``, turned into frames by the live view's own
    :class:`~mwip_ros.nodes.tools.foxglove_frames.FrameView`.  Returns the path and the number of frame trees seen;
    a bag without robot_state's topics raises ValueError naming what is missing."""
    from mwip_ros.bag.reader import raw_messages
    from mwip_ros.core.mobile_base.urdf import BASE_LINK
    from mwip_ros.nodes.tools.foxglove_frames import FRAME_TOPICS, FrameView
    view, description, trees, wheels = FrameView(), None, [], []
    for _, topic, data in raw_messages(bag, [f"/{t}" for t in FRAME_TOPICS]):
        leaf = topic.lstrip("/")
        got = view.feed(leaf, data)
        if leaf == "robot_description" and description is None and view.joints:   # a URDF the view could read
            from rclpy.serialization import deserialize_message
            description = deserialize_message(data, view.types[leaf]).data
        if got is None:
            continue
        stamp, tfs = got
        if any(tf.child == BASE_LINK for tf in tfs):
            trees.append((stamp, {tf.child: tf for tf in tfs}, list(wheels)))
        else:
            wheels[:] = tfs
    trees = [tree for tree in trees if tree[2]]   # placed once the wheels' joints have come
    if description is None or not trees:
        missing = [t for t, ok in (("robot_description (a URDF)", description is not None),
                                   ("odom with wheel_joint_states", bool(trees))) if not ok]
        raise ValueError(f"{bag}: no {' and no '.join(missing)}: record robot_state's topics "
                         "(run_experiment.sh --robot-state)")
    t0, t1 = trees[0][0], trees[-1][0]
    film = UrdfFilm(description, (t1 - t0) * 1e-9, path)
    for stamp, base, wheel_tfs in trees:
        film.see((stamp - t0) * 1e-9, [*base.values(), *wheel_tfs])
    return film.write(), len(trees)
