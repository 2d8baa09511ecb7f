"""run_offline: processors chained over a bag, without DDS, deterministic, bag topics replaced."""
import numpy as np
import pytest
from std_msgs.msg import String

from aircraft_docking_tracker.io.bag import BagReader, BagWriter, ns_to_stamp
from aircraft_docking_tracker.images import numpy_to_image, to_mono8
from aircraft_docking_tracker.object_table import DETECTION_DTYPE, cloud_to_table, table_to_cloud
from aircraft_docking_tracker.offline import OfflineRun, run
from aircraft_docking_tracker.ros.processing import MessageProcessor


class BrightSpotDetector(MessageProcessor):
    """image -> detections: one box around the brightest pixel."""
    inputs = {"image": "sensor_msgs/msg/Image"}
    outputs = {"detections": "sensor_msgs/msg/PointCloud2"}
    latest_only = frozenset({"image"})

    def process(self, topic, msg):
        grey = to_mono8(msg)
        y, x = np.unravel_index(np.argmax(grey), grey.shape)
        table = np.array([(x - 2, y - 2, 5, 5, grey.max() / 255, 0)], DETECTION_DTYPE)
        return [("detections", table_to_cloud(table, msg.header))]


class Counter(MessageProcessor):
    """detections -> summary: counts rows seen so far."""
    inputs = {"detections": "sensor_msgs/msg/PointCloud2"}
    outputs = {"summary": "std_msgs/msg/String"}

    def __init__(self):
        self.rows = 0

    def process(self, topic, msg):
        self.rows += len(cloud_to_table(msg, DETECTION_DTYPE))
        return [("summary", String(data=str(self.rows)))]

    def reset(self):
        self.rows = 0


def write_input(path, frames=10, with_detections=True):
    with BagWriter(path) as writer:
        for i in range(frames):
            image = np.zeros((20, 30), np.uint8)
            image[5 + i % 10, 3 + 2 * i] = 255
            msg = numpy_to_image(image, "mono8")
            msg.header.stamp = ns_to_stamp(1_000_000_000 + i * 100_000_000)
            writer.write("/cam0/image", msg, 1_000_000_000 + i * 100_000_000)
            if with_detections:  # stale detections from elsewhere: the run's own replace them
                writer.write("/cam0/detections", table_to_cloud(np.zeros(3, DETECTION_DTYPE), msg.header),
                             1_000_000_000 + i * 100_000_000 + 1)


def test_chained_processors_write_every_input_and_output(tmp_path):
    write_input(tmp_path / "in.mcap")
    processors = {"detector": BrightSpotDetector(), "counter": Counter()}
    runner = run(tmp_path / "in.mcap", tmp_path / "out.mcap", [], namespace="cam0", progress=False,
                 processors=processors)
    out = BagReader(tmp_path / "out.mcap")
    assert {t: i.count for t, i in out.topics.items()} == {"/cam0/image": 10, "/cam0/detections": 10, "/cam0/summary": 10}
    dets = [cloud_to_table(m, DETECTION_DTYPE) for _, m, _ in out.ros_messages(["/cam0/detections"])]
    assert [int(d["x"][0]) + 2 for d in dets] == [3 + 2 * i for i in range(10)]
    assert [m.data for _, m, _ in out.ros_messages(["/cam0/summary"])] == [str(i + 1) for i in range(10)]
    assert runner.stats["detector"].processed == 10 and runner.stats["counter"].processed == 10


def test_runs_are_deterministic(tmp_path):
    write_input(tmp_path / "in.mcap", with_detections=False)
    for name in ("a.mcap", "b.mcap"):
        run(tmp_path / "in.mcap", tmp_path / name, [], namespace="cam0", progress=False,
            processors={"detector": BrightSpotDetector(), "counter": Counter()})
    a = [(m.topic, m.log_time_ns, m.data) for m in BagReader(tmp_path / "a.mcap").messages()]
    b = [(m.topic, m.log_time_ns, m.data) for m in BagReader(tmp_path / "b.mcap").messages()]
    assert a == b and len(a) == 30


def test_bad_messages_are_counted_not_fatal():
    runner = OfflineRun({"detector": BrightSpotDetector()})
    bad = numpy_to_image(np.zeros((4, 4), np.uint8), "mono8")
    bad.encoding = "nonsense"
    assert runner.feed("image", bad) == []
    assert runner.stats["detector"].rejected_total == 1


def test_unknown_node_is_a_clear_error(tmp_path):
    write_input(tmp_path / "in.mcap", frames=1)
    with pytest.raises(ValueError, match="unknown node"):
        run(tmp_path / "in.mcap", tmp_path / "out.mcap", ["nope"], progress=False)


def test_partial_rejections_are_counted_offline_as_live():
    """Association drops NaN rows but processes the rest: both runners count it the same way."""
    from aircraft_docking_tracker.offline import build_processor

    runner = OfflineRun({"association": build_processor("association")})
    table = np.array([(10, 10, 5, 5, 0.9, 0), (np.nan, 1, 1, 1, 0.9, 0)], DETECTION_DTYPE)
    msg = table_to_cloud(table)
    msg.header.stamp = ns_to_stamp(1_000_000_000)
    assert [t for t, _ in runner.feed("detections", msg)] == ["tracks", "tracks/markers", "tracks/image_markers"]
    assert runner.stats["association"].rejected_total == 1
