"""plant_sim with ``backend: mujoco`` applies external_wrench's force.y (a lateral push) and torque.z (a yaw torque)
to the body (docs/theory.md 6.10, docs/graph.md): REP-103 signs seen on ``true_pose``. The realtime plant in this
process, its runner's ticks driven one by one (a push across processes, to a running plant: mwip_ctl push,
test/cli/test_ctl.py)."""
import pytest

pytest.importorskip("mujoco")

pytestmark = pytest.mark.node


def test_a_lateral_push_and_a_yaw_torque_reach_the_mujoco_body():
    from mwip_ros.msgs import layouts as L
    from nodeharness import NodeHarness, node_class, realtime_tick

    with NodeHarness(node_class("plant_sim"), "-p", "mode:=realtime", "-p", "duration_s:=0.0",
                     "-p", "initial.theta_b:=0.0", "-p", "backend:=mujoco", "-p", "actual.D_w_variance:=0.0",
                     "-p", "tau_ext1.amplitude:=0.0", "-p", "tau_ext2.amplitude:=0.0") as plant:  # upright, at rest
        node = plant.node
        node._start("the test drives the ticks")   # no controller: zero torque keeps it so

        def pose():
            return L.parse_pose(plant.sent("true_pose")[-1])[1]   # (x, y, z, yaw, pitch, roll)

        def ticks_until(cond, most=2000):   # 10 s of simulated time at most
            for _ in range(most):
                realtime_tick(node)
                if cond(pose()):
                    return True
            return False

        assert ticks_until(lambda p: node.plant.k >= 20)
        assert abs(pose()[1]) < 1e-6 and abs(pose()[5]) < 1e-6 and abs(pose()[3]) < 1e-6

        def pushed(fy, tz, until):
            plant.feed("external_wrench", L.encode_external_wrench(0.0, 0.0, fy, tz))   # held until the next one
            return ticks_until(until)

        # 3 kN to the left (+y) at the centre of gravity: the top goes left, a negative roll, and y grows
        assert pushed(3000.0, 0.0, lambda p: p[5] < -0.005 and p[1] > 1e-4), pose()
        assert pushed(0.0, 0.0, lambda p: abs(p[5]) < 1e-3), pose()   # let go: it settles back on two wheels
        yaw0 = pose()[3]
        assert pushed(0.0, 200.0, lambda p: p[3] > yaw0 + 1e-3), pose()   # counterclockwise seen from above
        plant.feed("external_wrench", L.encode_external_wrench(0.0, 0.0))
    out = plant.logs()
    assert "force.y 3000 N" in out and "torque.z 200 N m" in out and "Traceback" not in out
    assert "external wrench cleared" in out
