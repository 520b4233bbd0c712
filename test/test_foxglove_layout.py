"""config/foxglove_layout.json names only topics the graph has and fields their messages have.

The layout is Foxglove's layout file (Layouts > Import from file): ``configById`` holds each
panel's settings under ``Type!id``, ``layout`` the tree of splits that places them.  Every
topic a panel reads and every message path a plot draws (``/topic.field[i].sub{key==value}``)
is checked against the graph's topic table (:mod:`mwip_ros.msgs.topics`) and the installed
rosidl message classes (``get_fields_and_field_types()`` / ``SLOT_TYPES``), so a renamed
topic or field breaks this test, not a user's plot.
"""
from __future__ import annotations

import json
import re
from typing import Dict, Iterator, List, Tuple

import pytest
from rosidl_parser.definition import AbstractGenericString, AbstractNestedType, Array, BasicType, NamespacedType

from graphproc import REPO
from mwip_ros.msgs.layouts import JOINT_NAMES
from mwip_ros.msgs.topics import GRAPH_TOPICS, SYSTEM_TOPICS, msg_class

pytestmark = pytest.mark.unit

LAYOUT = REPO / "config" / "foxglove_layout.json"
TOPICS = {"/" + name.lstrip("/"): type_name for name, type_name in {**GRAPH_TOPICS, **SYSTEM_TOPICS}.items()}
NUMERIC = {"float", "double", "long double", "boolean", "octet", "int8", "uint8", "int16", "uint16", "int32",
           "uint32", "int64", "uint64"}

_PATH = re.compile(r"^(/[A-Za-z0-9_/]*[A-Za-z0-9_])((?:[.\[{].*?)?)(@[a-zA-Z]+)?$")
_TOKEN = re.compile(r"\.(?P<field>[A-Za-z_][A-Za-z0-9_]*)"
                    r"|\[(?P<lo>-?\d*)(?P<colon>:?)(?P<hi>-?\d*)\]"
                    r"|\{(?P<key>[A-Za-z_][A-Za-z0-9_]*)\s*(?:==|!=|<=|>=|<|>)\s*(?P<literal>[^}]+)\}")


class PathError(ValueError):
    pass


def _fields(cls) -> Dict[str, object]:
    """{field name: rosidl type} of a generated message class."""
    return dict(zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES))


def _class(t: NamespacedType):
    return msg_class("/".join([*t.namespaces, t.name]))


def walk(path: str):
    """The rosidl type that message path ``path`` ends at; PathError naming the first part that does not exist."""
    m = _PATH.match(path)
    if not m:
        raise PathError(f"{path!r}: not a message path (/topic.field...)")
    topic, rest = m.group(1), m.group(2)
    if topic not in TOPICS:
        raise PathError(f"{path!r}: {topic} is not a topic of the graph ({', '.join(sorted(TOPICS))})")
    *namespaces, name = TOPICS[topic].split("/")
    current = NamespacedType(namespaces, name)
    pos = 0
    while pos < len(rest):
        tok = _TOKEN.match(rest, pos)
        if not tok:
            raise PathError(f"{path!r}: cannot read {rest[pos:]!r}")
        pos = tok.end()
        here = path[:len(topic) + pos]
        if tok.group("field"):
            if not isinstance(current, NamespacedType):
                raise PathError(f"{here!r}: .{tok.group('field')} of something that is not a message")
            fields = _fields(_class(current))
            if tok.group("field") not in fields:
                raise PathError(f"{here!r}: {'/'.join([*current.namespaces, current.name])} has no field "
                                f"{tok.group('field')!r} (fields: {', '.join(fields)})")
            current = fields[tok.group("field")]
        elif tok.group("key"):
            if not isinstance(current, NamespacedType):
                raise PathError(f"{here!r}: a filter on something that is not a message")
            fields = _fields(_class(current))
            key = fields.get(tok.group("key"))
            literal = tok.group("literal").strip()
            if key is None:
                raise PathError(f"{here!r}: no field {tok.group('key')!r} to filter on")
            quoted = literal[:1] in "'\"" and literal[-1:] == literal[:1] and len(literal) >= 2
            if quoted != isinstance(key, AbstractGenericString) or not (quoted or isinstance(key, BasicType)):
                raise PathError(f"{here!r}: {literal} cannot be compared with field {tok.group('key')!r}")
        else:  # [i] or [a:b]
            if not isinstance(current, AbstractNestedType):
                raise PathError(f"{here!r}: an index on something that is not an array")
            if not tok.group("colon"):
                if not tok.group("lo"):
                    raise PathError(f"{here!r}: an empty index")
                i = int(tok.group("lo"))
                size = current.size if isinstance(current, Array) else None
                if size is not None and not -size <= i < size:
                    raise PathError(f"{here!r}: index {i} of an array of {size}")
            current = current.value_type
    return current


def check_plot_path(path: str) -> None:
    leaf = walk(path)
    if not (isinstance(leaf, BasicType) and leaf.typename in NUMERIC):
        raise PathError(f"{path!r}: ends at {type(leaf).__name__} {getattr(leaf, 'typename', '')}, not a number "
                        "a plot can draw")


def _leaves(node) -> Iterator[str]:
    if isinstance(node, str):
        yield node
        return
    assert set(node) >= {"first", "second", "direction"}, node
    assert node["direction"] in ("row", "column") and 0 < node.get("splitPercentage", 50) < 100, node
    yield from _leaves(node["first"])
    yield from _leaves(node["second"])


def references(doc) -> Tuple[List[Tuple[str, str]], List[Tuple[str, str]]]:
    """([(panel, message path a plot draws)], [(panel, topic a panel reads whole)])."""
    paths, topics = [], []
    for panel, cfg in doc["configById"].items():
        kind = panel.split("!", 1)[0]
        for series in cfg.get("paths", []):
            paths.append((panel, series["value"]))
        for topic in cfg.get("topics", {}):
            topics.append((panel, topic))
        if "topicToRender" in cfg:
            topics.append((panel, cfg["topicToRender"]))
        assert kind in ("3D", "Plot", "DiagnosticSummary", "DiagnosticStatusPanel"), panel
    return paths, topics


@pytest.fixture(scope="module")
def doc():
    return json.loads(LAYOUT.read_text())


def test_the_layout_is_a_foxglove_layout_that_places_every_panel_once(doc):
    assert {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"} <= set(doc)
    placed = list(_leaves(doc["layout"]))
    assert sorted(placed) == sorted(doc["configById"]) and len(set(placed)) == len(placed)


def test_every_topic_and_message_path_exists(doc):
    paths, topics = references(doc)
    assert paths and topics
    for panel, path in paths:
        check_plot_path(path)   # raises, naming the path
        assert doc["configById"][panel]["paths"], panel
    kinds = {panel.split("!")[0]: [] for panel, _ in topics}
    for panel, topic in topics:
        assert topic in TOPICS, (panel, topic)
        kinds[panel.split("!")[0]].append(TOPICS[topic])
    assert kinds["3D"] == ["visualization_msgs/msg/MarkerArray", "std_msgs/msg/String"]   # markers, the URDF
    assert kinds["DiagnosticSummary"] == kinds["DiagnosticStatusPanel"] == ["diagnostic_msgs/msg/DiagnosticArray"]


def test_the_layout_shows_what_the_docs_say(doc):
    """The robot in frame world, its URDF on the odom frames; theta_b, theta_w', u, each tau_hat beside the true
    tau_d and the estimated pitch beside the true one (layouts.py:
    joint_states holds [wheel, body_pitch]; torque.x / torque.y are components 1 / 2)."""
    from mwip_ros.nodes.tools.robot_markers import FRAME
    three_d = [cfg for panel, cfg in doc["configById"].items() if panel.startswith("3D!")]
    assert len(three_d) == 2 and three_d[0]["followTf"] == FRAME and three_d[0]["topics"]["/robot_markers"]["visible"]
    # the URDF (robot_state's robot_description) on the frames the server sends (foxglove_frames), its grid on odom
    from mwip_ros.core.mobile_base.urdf import BASE_LINK, ODOM_FRAME
    urdf = three_d[1]
    assert urdf["followTf"] == BASE_LINK and urdf["topics"] == {"/robot_description": {"visible": True}}
    assert urdf["layers"]["mwip_grid"]["frameId"] == ODOM_FRAME
    plotted = {tuple(s["value"] for s in cfg["paths"]) for panel, cfg in doc["configById"].items()
               if panel.startswith("Plot!")}
    b, w = JOINT_NAMES.index("body_pitch"), JOINT_NAMES.index("wheel")
    assert plotted == {
        (f"/joint_states.position[{b}]",),
        (f"/joint_states.velocity[{w}]",),
        ("/wheel_torque_cmd.data",),
        ("/disturbance_estimate.wrench.torque.x", "/lumped_disturbance.wrench.torque.x"),
        ("/disturbance_estimate.wrench.torque.y", "/lumped_disturbance.wrench.torque.y"),
        # raw sensors (docs/theory.md 6.4): the true pitch beside the state_estimator's, matched by their stamps
        (f"/true_joint_states.position[{b}]", f"/joint_states.position[{b}]"),
    }
    pitch = doc["configById"]["Plot!pitch_estimate"]["paths"]
    assert {s["timestampMethod"] for s in pitch} == {"headerStamp"}


@pytest.mark.parametrize("path, reason", [
    ("/joint_states.positon[1]", "has no field 'positon'"),
    ("/joint_state.position[1]", "not a topic of the graph"),
    ("/joint_states.position.x", "not a message"),
    ("/wheel_torque_cmd.data[0]", "not an array"),
    ("/disturbance_estimate.wrench.torque", "not a number"),
    ("/disturbance_estimate.wrench.torque.w", "has no field 'w'"),
    ("/joint_states.header.frame_id", "not a number"),
    ("/joint_states.name[0]", "not a number"),
    ("/diagnostics.status[:]{nam==\"x\"}.level", "no field 'nam'"),
    ("/diagnostics.status[:]{level==\"x\"}.level", "cannot be compared"),
    ("/diagnostics.status[:].values[0].value", "not a number"),
    ("joint_states.position[1]", "not a message path"),
])
def test_the_checker_rejects_what_does_not_exist(path, reason):
    with pytest.raises(PathError, match=re.escape(reason)):
        check_plot_path(path)


@pytest.mark.parametrize("path", ["/diagnostics.status[:]{name==\"/plant_sim\"}.level", "/clock.clock.sec",
                                  "/joint_states.position[-1]", "/joint_states.header.stamp.nanosec@derivative"])
def test_the_checker_accepts_real_paths(path):
    check_plot_path(path)
