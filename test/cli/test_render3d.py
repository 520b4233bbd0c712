"""``mwip_sim --render``: the MuJoCo robot drawn in 3D (issue 32's rendered frame).  Refused in one line before the run
(not the MuJoCo backend, a suffix it cannot write, an output that exists without --force); drawing never changes
the run (the CSV with --render equals the CSV without, to the bit); the sheet shows the robot in every frame and
the path it drove.  Where MuJoCo has no OpenGL (no EGL, no OSMesa) the drawing tests are skipped with that reason
(the refusal itself is tested)."""
import numpy as np
import pytest

from mwip_ros.cli import render3d, sim
from mwip_ros.optional import missing
from mwip_ros.params.paths import default_params_file

if missing("mujoco"):   # through the project's import: headless, MuJoCo then draws with EGL (optional.required)
    pytest.skip(missing("mujoco"), allow_module_level=True)
pytestmark = pytest.mark.unit

PAPER = str(default_params_file())
SQUARE = str(default_params_file().with_name("square.yaml"))
NO_GL = render3d.gl_refusal()
needs_gl = pytest.mark.skipif(NO_GL is not None, reason=str(NO_GL))


def _sim(capsys, *argv):
    code = sim.main([*argv, "-q"])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_render_refuses_the_rk4_backend_in_one_line_naming_it(capsys, tmp_path):
    code, _, err = _sim(capsys, "--duration", "0.1", "--render", str(tmp_path / "r.png"))
    assert code == 2
    assert "--render draws the MuJoCo model, and plant_sim.backend is rk4" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "r.png").exists()


def test_render_refuses_a_suffix_it_cannot_write(capsys, tmp_path):
    code, _, err = _sim(capsys, "--params", PAPER, SQUARE, "--duration", "0.1", "--render", str(tmp_path / "r.mp4"))
    assert code == 2 and "must end in .gif" in err


def test_render_never_overwrites_without_force(capsys, tmp_path):
    out = tmp_path / "r.png"
    out.write_bytes(b"mine")
    code, _, err = _sim(capsys, "--params", PAPER, SQUARE, "--duration", "0.1", "--render", str(out))
    assert code == 2 and "--force" in err and out.read_bytes() == b"mine"


@needs_gl
def test_drawing_does_not_change_the_run_and_the_sheet_shows_the_robot_driving(capsys, tmp_path):
    plain, drawn, sheet = tmp_path / "plain.csv", tmp_path / "drawn.csv", tmp_path / "robot.png"
    args = ["--params", PAPER, SQUARE, "--law", "dscndo", "--duration", "12"]
    assert _sim(capsys, *args, "--csv", str(plain))[0] == 0
    code, out, _ = _sim(capsys, *args, "--csv", str(drawn), "--render", str(sheet))
    assert code == 0 and f"wrote {sheet}" in out
    assert plain.read_bytes() == drawn.read_bytes()
    from PIL import Image
    img = np.asarray(Image.open(sheet).convert("RGB")).astype(int)
    w, h = render3d.SIZE
    assert img.shape == (2 * h, 3 * w, 3)
    body = np.array(render3d._BODY_RGBA[:3]) * 255
    trail = np.array(render3d._TRAIL_RGBA[:3]) * 255
    tiles = [img[r * h:(r + 1) * h, c * w:(c + 1) * w] for r in range(2) for c in range(3)]

    def share(tile, rgb, tol):   # the share of a tile's pixels near a colour (shading moves it a little)
        return float(np.mean(np.abs(tile - rgb).max(axis=2) < tol))

    # the body (orange) in every frame, a few % of it; the blue path absent at t = 0, drawn once the robot drove
    assert all(share(t, body, 90) > 0.003 for t in tiles), [share(t, body, 90) for t in tiles]
    assert share(tiles[0], trail, 70) < 1e-4 < share(tiles[-1], trail, 70)


@needs_gl
def test_a_gif_plays_the_run_in_real_time(capsys, tmp_path):
    out = tmp_path / "robot.gif"
    code, _, _ = _sim(capsys, "--params", PAPER, SQUARE, "--law", "dscndo", "--duration", "1", "--render", str(out))
    assert code == 0
    from PIL import Image
    gif = Image.open(out)
    assert gif.n_frames == 21   # t = 0, 0.05, ..., 1.0 s
    assert gif.info["duration"] == 50


def _robot_state_bag(path, seconds=2.0, rate=50):
    """A bag as robot_state records it: the URDF, then odom driving 1 m/s along x and the wheels turning."""
    from nav_msgs.msg import Odometry
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    from bagcheck import ENDPOINT_QOS
    from mwip_ros import params as P
    from mwip_ros.bag import BagWriter, qos_profiles_yaml
    from mwip_ros.core.mobile_base import urdf as U
    model = U.robot_model(P.merged_values(P.load_param_files([PAPER, SQUARE])))
    qos = qos_profiles_yaml([ENDPOINT_QOS])
    with BagWriter(path) as bag:
        for name, kind in (("/robot_description", "std_msgs/msg/String"), ("/odom", "nav_msgs/msg/Odometry"),
                           ("/wheel_joint_states", "sensor_msgs/msg/JointState")):
            bag.add_topic(name, kind, qos, "")
        bag.write("/robot_description", serialize_message(String(data=U.urdf(model))), 1)
        for k in range(int(seconds * rate) + 1):
            t = k / rate
            ns = int(round(t * 1e9)) + 1_000_000
            js = JointState(name=list(U.WHEEL_JOINTS), position=[t / model.r, t / model.r])
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            bag.write("/wheel_joint_states", serialize_message(js), ns)
            o = Odometry()
            o.header.stamp.sec, o.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            o.header.frame_id, o.child_frame_id = "odom", "base_link"
            o.pose.pose.position.x, o.pose.pose.position.z, o.pose.pose.orientation.w = t, model.r, 1.0
            bag.write("/odom", serialize_message(o), ns)
    return model


def _tiles(path):
    from PIL import Image
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    w, h = render3d.SIZE
    return [img[r * h:(r + 1) * h, c * w:(c + 1) * w] for r in range(img.shape[0] // h) for c in range(3)]


@needs_gl
def test_a_bag_of_robot_state_is_drawn_from_its_urdf_and_frames(capsys, tmp_path):
    _robot_state_bag(tmp_path / "bag")
    out = tmp_path / "robot.png"
    drawn, trees = render3d.film_bag(tmp_path / "bag", out)
    assert drawn == out and trees == 101
    blue = np.array([0.1, 0.4, 0.8]) * 255   # the URDF's body material
    trail = np.array(render3d._TRAIL_RGBA[:3]) * 255
    tiles = _tiles(out)
    assert len(tiles) == render3d.SHEET

    def share(tile, rgb, tol):
        return float(np.mean(np.abs(tile - rgb).max(axis=2) < tol))
    assert all(share(t, blue, 60) > 0.003 for t in tiles), [share(t, blue, 60) for t in tiles]
    assert share(tiles[0], trail, 40) < 1e-4 < share(tiles[-1], trail, 40)


def test_a_bag_without_robot_state_is_refused_naming_what_is_missing(tmp_path):
    from bagcheck import write_graph_bag
    write_graph_bag(tmp_path / "bag", n=3)   # its robot_description is no URDF
    with pytest.raises(ValueError, match=r"no robot_description \(a URDF\).*run_experiment.sh --robot-state"):
        render3d.film_bag(tmp_path / "bag", tmp_path / "r.png")
    assert not (tmp_path / "r.png").exists()


@needs_gl
def test_mwip_report_render_writes_the_drawing_and_refuses_two_inputs(capsys, tmp_path):
    from mwip_ros.cli import report
    _robot_state_bag(tmp_path / "bag", seconds=1.0)
    code = report.main([str(tmp_path / "bag"), str(tmp_path / "bag"), "--out", str(tmp_path / "rep"),
                        "--render", str(tmp_path / "r.gif")])
    assert code == 2 and "--render draws one bag" in capsys.readouterr().err
