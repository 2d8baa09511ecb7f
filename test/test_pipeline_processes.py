"""The executables as separate processes, started the way `ros2 run` does, with --ros-args
parameters, a parameter file, a namespace and remapping; player and recorder processes too."""
import time

import numpy as np
import pytest

from aircraft_docking_tracker.io.bag import BagReader
from aircraft_docking_tracker.config import package_config_dir
from aircraft_docking_tracker.object_table import TRACK_DTYPE, cloud_to_table
from aircraft_docking_tracker.offline import run
from aircraft_docking_tracker.processes import NodeProcess, executable_path, wait_until

from pipeline_helpers import uav_bag

pytestmark = pytest.mark.ros


def test_association_process_with_ros_args_matches_offline(tmp_path):
    try:
        executable_path("association_node")
    except FileNotFoundError as exc:
        pytest.skip(str(exc))
    bag = uav_bag(tmp_path / "uav.mcap", frames=60)
    recording = tmp_path / "rec"
    node = NodeProcess("association_node", namespace="cam7", params_file=package_config_dir() / "association.yaml",
                       parameters={"output.trail_length": 5}, remaps={"detections": "dets_in"},
                       log_path=tmp_path / "node.log")
    recorder = NodeProcess("mcap_record", args=["/cam7/dets_in", "/cam7/tracks", "-o", recording],
                           log_path=tmp_path / "record.log")
    with node, recorder:
        assert wait_until(lambda: "recording /cam7/tracks" in (tmp_path / "record.log").read_text(), 30), \
            (tmp_path / "record.log").read_text()
        player = NodeProcess("mcap_play", args=[bag, "--topics", "detections", "--remap", "detections:=/cam7/dets_in",
                                                "--rate", "2", "--wait-for-subscribers", "20", "--min-subscribers", "2",
                                                "--delay", "2"],  # the node and the recorder
                             log_path=tmp_path / "play.log").start()
        assert player.wait(120) == 0, (tmp_path / "play.log").read_text()
        time.sleep(1.5)
    assert node.process.returncode == 0, (tmp_path / "node.log").read_text()
    assert recorder.process.returncode == 0, (tmp_path / "record.log").read_text()
    live = [cloud_to_table(m, TRACK_DTYPE) for _, m, _ in BagReader(recording).ros_messages(["/cam7/tracks"])]
    run(bag, tmp_path / "offline.mcap", ["association"], progress=False)
    offline = [cloud_to_table(m, TRACK_DTYPE) for _, m, _ in BagReader(tmp_path / "offline.mcap").ros_messages(["/tracks"])]
    assert len(live) == len(offline) == 60
    for a, b in zip(live, offline):
        np.testing.assert_array_equal(a, b)


def test_bad_parameter_on_the_command_line_is_refused_and_the_node_runs(tmp_path):
    log = tmp_path / "node.log"
    with NodeProcess("association_node", parameters={"cost_gate": 99.0}, log_path=log) as node:
        assert wait_until(lambda: "keeping the default" in log.read_text(), 30), log.read_text()
        time.sleep(0.5)
        assert node.running()
    assert node.process.returncode == 0
