"""mwip_report's animation.gif (mwip_ros.cli.animation), read back with Pillow and measured in pixels.

The runs are synthetic trajectory tables whose theta_b and theta_w are known formulas, so every
expected angle below comes from the formula, not from the code under test.
"""
import math

import numpy as np
import pytest
from PIL import Image

from mwip_ros.cli import animation as A
from mwip_ros.cli import report
from mwip_ros.core.closed_loop.trajectory import TRAJECTORY_COLUMNS, Trajectory
from mwip_ros.runs import write_csv

pytestmark = pytest.mark.unit

H = 0.005          # the sample period [s]
FPS = 10           # frame k shows t = k / FPS: a sample time
WHEEL_RATE = -4.0  # theta_w = WHEEL_RATE t: 2 m backwards in 2 s; the spoke >= 50 deg from the rod at 0.7, 1, 1.3 s


def bump(t, amplitude):
    """0 outside [0.5, 1.5] s, a half sine of ``amplitude`` [rad] inside."""
    return np.where((t >= 0.5) & (t <= 1.5), amplitude * np.sin(np.pi * (t - 0.5)), 0.0)


def make_run(label, theta_b_of_t, t_end=2.0):
    t = np.arange(int(round(t_end / H)) + 1) * H
    cols = {c: np.zeros_like(t) for c in TRAJECTORY_COLUMNS}
    cols.update(t=t, theta_w=WHEEL_RATE * t, theta_b=theta_b_of_t(t), dtheta_w=np.full_like(t, WHEEL_RATE))
    return Trajectory(label, cols, False, H)


def write_runs(tmp_path, runs):
    paths = []
    for run in runs:
        paths.append(str(tmp_path / f"{run.label}.csv"))
        write_csv(run, paths[-1])
    return paths


def frames(gif, durations=None):
    """(the frames as RGB arrays, the size, the first frame's duration [ms]); ``durations``, a list, gets
    every frame's."""
    with Image.open(gif) as im:
        out, each = [], []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB")))
            each.append(im.info.get("duration"))
        if durations is not None:
            durations[:] = each
        return out, im.size, each[0]


def panel(frame, j, n):
    w = frame.shape[1] // n
    return frame[:, j * w:(j + 1) * w]


def mask(img, colour):
    return np.all(img == np.array(colour, dtype=np.uint8), axis=-1)


def reddish(img):
    """The pixels of FELL_COLOUR text, antialiased edges included (nothing else drawn is this red)."""
    rgb = img.astype(int)
    return (rgb[..., 0] > 150) & (rgb[..., 1] < 110) & (rgb[..., 2] < 110)


def rod_axis(img):
    """(the axle's pixel, the rod's unit direction towards its top (x right, y up)) from the rod's colour."""
    ys, xs = np.nonzero(mask(img, A.ROD_COLOUR))
    assert len(xs) > 100, "no rod drawn"
    pts = np.column_stack([xs, -ys]).astype(float)
    centre = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - centre)
    u = vt[0] if vt[0][1] > 0 else -vt[0]
    proj = (pts - centre) @ u
    return centre + proj.min() * u, u


def drawn_angle(u):
    """The angle from upright of a direction (x right, y up), positive towards +x."""
    return math.atan2(u[0], u[1])


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """DSC-like and DSCNDO-like runs equal but for theta_b in [0.5, 1.5] s; the report with its GIF."""
    tmp = tmp_path_factory.mktemp("anim")
    runs = [make_run("wobbly", lambda t: bump(t, 0.35)), make_run("calm", lambda t: bump(t, -0.5))]
    out = tmp / "rep"
    assert report.main(write_runs(tmp, runs) + ["--out", str(out), "--gif-fps", str(FPS)]) == 0
    return runs, out


def test_one_frame_per_tenth_of_a_second_side_by_side_panels(two_runs):
    runs, out = two_runs
    each = []
    imgs, size, duration = frames(out / "animation.gif", each)
    assert len(imgs) == int(2.0 * FPS) + 1                # t = 0, 0.1, .., 2.0 s
    assert duration == 1000 // FPS                         # played in real time
    assert each[:-1] == [1000 // FPS] * (len(imgs) - 1) and each[-1] == A.HOLD_END_MS   # the end is held
    assert size == (2 * A.PANEL_SIZE[0], A.HEADER + A.PANEL_SIZE[1]) and size[0] <= 800   # one panel per run
    assert "animation.gif" in (out / "metrics.md").read_text()


def test_the_rod_is_drawn_at_theta_b_and_the_spoke_at_theta_w(two_runs):
    runs, out = two_runs
    imgs, _, _ = frames(out / "animation.gif")
    for k in (7, 10, 13):
        t = k / FPS
        for j, run in enumerate(runs):
            img = panel(imgs[k], j, 2)
            axle, u = rod_axis(img)
            theta_b = float(np.interp(t, run.t, run["theta_b"]))
            assert drawn_angle(u) == pytest.approx(theta_b, abs=math.radians(1.5)), (k, run.label)
            ys, xs = np.nonzero(mask(img, A.SPOKE_COLOUR))
            assert len(xs) > 30
            spoke = np.array([xs.mean(), -ys.mean()]) - axle
            assert wrap(drawn_angle(spoke) - WHEEL_RATE * t) == pytest.approx(0.0, abs=math.radians(4)), (k, run.label)


def test_the_panels_differ_where_the_runs_differ_and_the_view_follows_the_robot(two_runs):
    runs, out = two_runs
    imgs, _, _ = frames(out / "animation.gif")
    rods = [[mask(panel(img, j, 2), A.ROD_COLOUR) for j in (0, 1)] for img in imgs]
    for k in (0, 3, 16, 20):          # theta_b = 0 in both runs: the same rod
        assert (rods[k][0] == rods[k][1]).all()
    for k in (7, 10, 13):             # theta_b differs: so does the rod, by many pixels
        assert (rods[k][0] != rods[k][1]).sum() > 200
    # the wheel rolled 2 m, the body upright at t = 0 and t = 2: the same rod in the same place
    assert (rods[0][0] == rods[20][0]).all() and rods[20][0].sum() > 100
    axle, _ = rod_axis(panel(imgs[20], 0, 2))
    assert axle[0] == pytest.approx(A.PANEL_SIZE[0] / 2, abs=3)


def test_a_fallen_run_is_marked_from_its_fall_and_holds_its_last_pose(tmp_path):
    rate = 1.2 * report.FALL_ANGLE                     # [rad/s]: |theta_b| passes the fall angle at t = 1 / 1.2 s
    crossing = report.FALL_ANGLE / rate
    falling = make_run("falls", lambda t: -rate * t, t_end=1.0)   # the table goes on past the crossing
    runs = [make_run("steady", lambda t: np.zeros_like(t)), falling]
    out = tmp_path / "rep"
    assert report.main(write_runs(tmp_path, runs) + ["--out", str(out), "--gif-fps", str(FPS)]) == 0
    imgs, _, _ = frames(out / "animation.gif")
    assert len(imgs) == int(2.0 * FPS) + 1             # until the longer run ends
    first_marked = math.ceil(crossing / H) * H        # the first sample beyond the fall angle
    for k, img in enumerate(imgs):
        red = [reddish(panel(img, j, 2)[:A.HEADER + 20]).sum() for j in (0, 1)]
        assert red[0] == 0
        assert (red[1] > 20) == (k / FPS >= first_marked - 1e-9), k
    last = round(1.0 * FPS)                            # the falling run ended: its last pose stays
    held = [mask(panel(img, 1, 2), A.ROD_COLOUR) for img in imgs[last:]]
    assert all((m == held[0]).all() for m in held)
    _, u = rod_axis(panel(imgs[-1], 1, 2))
    assert drawn_angle(u) == pytest.approx(-rate * 1.0, abs=math.radians(1.5))


def test_no_animation_writes_no_gif(tmp_path):
    paths = write_runs(tmp_path, [make_run("a", lambda t: bump(t, 0.1))])
    assert report.main(paths + ["--out", str(tmp_path / "rep"), "--no-animation"]) == 0
    assert (tmp_path / "rep" / "metrics.md").is_file() and not (tmp_path / "rep" / "animation.gif").exists()
    assert "animation.gif" not in (tmp_path / "rep" / "metrics.md").read_text()
    with pytest.raises(SystemExit):
        report.main(paths + ["--out", str(tmp_path / "rep2"), "--gif-fps", "0"])


def test_the_robot_is_sized_by_the_schema_defaults_nominal_model():
    from mwip_ros.params import PAPER_NOMINAL
    nominal = A.default_nominal()
    assert (nominal.r, nominal.l) == (PAPER_NOMINAL["r"], PAPER_NOMINAL["l"])


def test_a_long_run_gets_fewer_frames_still_in_real_time_and_a_row_without_state_draws_nothing(tmp_path,
                                                                                               monkeypatch):
    monkeypatch.setattr(A, "MAX_FRAMES", 30)
    run = make_run("long", lambda t: np.full_like(t, 0.2), t_end=10.0)
    run.columns["theta_b"][-1] = np.nan                 # the last row has no state: the one before stays
    n = A.write_gif([run], tmp_path / "a.gif", fps=20)
    imgs, size, duration = frames(tmp_path / "a.gif")
    assert n == len(imgs) and 25 <= n <= 30
    assert duration * (n - 1) == pytest.approx(10_000, rel=0.1)   # 10 s of run in about 10 s
    _, u = rod_axis(imgs[-1])
    assert drawn_angle(u) == pytest.approx(0.2, abs=math.radians(1.5))
