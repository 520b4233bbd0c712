"""A robot_description whose origin is not three numbers (issue 46 item 6): the URDF reader refuses it naming the
joint, the live view's frames reject it and go on (before: ``rpy="0 0"`` or ``xyz="0 0"`` raised a TypeError in the
subscription callback for each message), and a description beyond the bound is not parsed."""
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from mwip_ros.core.mobile_base.urdf import joint_transforms, urdf_joints
from mwip_ros.nodes.tools.foxglove_frames import FrameView

pytestmark = pytest.mark.unit


def test_a_description_whose_origin_is_not_three_numbers_is_rejected_not_raised():
    for bad in ('rpy="0 0"', 'xyz="0 0"', 'xyz="0 0 nan"', 'rpy="a b c"', 'xyz="0 0 0 0"'):
        text = (f'<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="continuous"><parent '
                f'link="a"/><child link="b"/><origin {bad}/><axis xyz="0 1 0"/></joint></robot>')
        with pytest.raises(ValueError, match="'j'"):
            urdf_joints(text)
        view = FrameView()
        view.feed("robot_description", serialize_message(String(data=text)))
        js = JointState(name=["j"], position=[0.1])
        assert view.feed("wheel_joint_states", serialize_message(js)) is None   # no joints: nothing, no traceback
        assert view.rejected == 1
    good = text.replace(bad, 'xyz="0 0 0" rpy="0 0 0"')
    assert len(joint_transforms(urdf_joints(good), {"j": 0.1})) == 1
    with pytest.raises(ValueError, match="larger than"):
        urdf_joints("<robot>" + " " * (2 << 20) + "</robot>")
