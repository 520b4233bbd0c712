"""plant_sim with ``backend: mujoco`` applies external_wrench's force.y (a lateral push) and torque.z (a yaw torque)
to the body (docs/theory.md 6.10, docs/graph.md): REP-103 signs seen on ``true_pose``."""
import pytest

pytest.importorskip("mujoco")

from graphproc import Graph  # noqa: E402

pytestmark = pytest.mark.graph


def test_a_lateral_push_and_a_yaw_torque_reach_the_mujoco_body(tmp_path):
    from geometry_msgs.msg import PoseStamped, Wrench
    from injector import Injector, health, wait_matched
    from mwip_ros.msgs import layouts as L

    with Graph(tmp_path) as g:
        plant = g.start("plant_sim", "-p", "mode:=realtime", "-p", "duration_s:=0.0", "-p", "initial.theta_b:=0.0",
                        "-p", "backend:=mujoco", "-p", "actual.D_w_variance:=0.0", "-p", "tau_ext1.amplitude:=0.0",
                        "-p", "tau_ext2.amplitude:=0.0")   # upright, at rest: no torque keeps it so
        with Injector(g.domain_id) as inj:
            wr = inj.publisher("external_wrench", Wrench)
            poses = inj.record("true_pose", PoseStamped)
            latest = health(inj)
            assert inj.wait(lambda: wr.get_subscription_count() >= 1 and len(poses) > 20, 60), plant.output()
            # each wrench is sent once: the plant's (volatile) reader must have matched this publisher
            assert wait_matched(inj, latest, "/plant_sim", {"/external_wrench": 1}), latest.get("/plant_sim")
            pose = lambda: L.parse_pose(poses[-1])[1]   # noqa: E731  (x, y, z, yaw, pitch, roll)
            assert abs(pose()[1]) < 1e-6 and abs(pose()[5]) < 1e-6 and abs(pose()[3]) < 1e-6

            def pushed(fy, tz, until):
                wr.publish(L.encode_external_wrench(0.0, 0.0, fy, tz))   # held until the next wrench
                return inj.wait(lambda: until(pose()), 30)

            # 3 kN to the left (+y) at the centre of gravity: the top goes left, a negative roll, and y grows
            assert pushed(3000.0, 0.0, lambda p: p[5] < -0.005 and p[1] > 1e-4), (pose(), plant.output()[-2000:])
            assert pushed(0.0, 0.0, lambda p: abs(p[5]) < 1e-3), pose()   # let go: it settles back on two wheels
            yaw0 = pose()[3]
            assert pushed(0.0, 200.0, lambda p: p[3] > yaw0 + 1e-3), pose()   # counterclockwise seen from above
            wr.publish(L.encode_external_wrench(0.0, 0.0))
        code = plant.stop()
    out = plant.output()
    assert code == 0, out
    assert "force.y 3000 N" in out and "torque.z 200 N m" in out and "Traceback" not in out
