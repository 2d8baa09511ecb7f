"""Launch-free integration: nodes in one process, fed by the player from scenario bags, recorded,
scored against the bags' ground truth; live outputs equal the offline runner's."""
import numpy as np
import pytest

from aircraft_docking_tracker.io.bag import BagReader
from aircraft_docking_tracker.docking.tracker import DockingConfig
from aircraft_docking_tracker.docking_tracker_node import DockingTrackerNode
from aircraft_docking_tracker.evaluation.evaluate import EvaluateConfig, evaluate_bags
from aircraft_docking_tracker.object_table import TRACK_DTYPE, cloud_to_table
from aircraft_docking_tracker.offline import build_processor, run
from aircraft_docking_tracker.sot_track import open_sequence, score_run, track
from multi_target_tracker.association_node import AssociationNode
from rclpy.parameter import Parameter

from pipeline_helpers import docking_bag, first_polygon_box, run_live, uav_bag

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scenes")
    return {"uav": uav_bag(folder / "uav.mcap"), "docking": docking_bag(folder / "docking.mcap", frames=60)}


def test_association_live_equals_offline_and_tracks_the_scene(scenes, tmp_path):
    live = tmp_path / "live.mcap"
    run_live([lambda ctx: AssociationNode(context=ctx, namespace="uav")], scenes["uav"], live, "uav",
             record_topics=["detections", "tracks", "ground_truth"], play_topics=["detections", "ground_truth"],
             rate=2.0,
             expect={"tracks": BagReader(scenes["uav"]).topics["detections"].count})
    offline = tmp_path / "offline.mcap"
    run(scenes["uav"], offline, ["association"], progress=False)
    live_tracks = [cloud_to_table(m, TRACK_DTYPE) for _, m, _ in BagReader(live).ros_messages(["/uav/tracks"])]
    offline_tracks = [cloud_to_table(m, TRACK_DTYPE) for _, m, _ in BagReader(offline).ros_messages(["/tracks"])]
    assert len(live_tracks) == len(offline_tracks) == BagReader(scenes["uav"]).topics["detections"].count
    for a, b in zip(live_tracks, offline_tracks):
        np.testing.assert_array_equal(a, b)
    scores = evaluate_bags(live, config=EvaluateConfig(namespace="uav"))  # ground truth recorded alongside
    assert scores["mot"]["mota"] > 0.6, scores["mot"]
    assert scores["mot"]["idf1"] > 0.6, scores["mot"]


def test_docking_tracker_live_equals_offline_and_follows_the_aircraft(scenes, tmp_path):
    live = tmp_path / "dock.mcap"
    box = first_polygon_box(scenes["docking"])
    nodes, report = run_live(
        [lambda ctx: DockingTrackerNode(context=ctx, namespace="dock",
                                        parameter_overrides=[Parameter("initial_box", value=box)])],
        scenes["docking"], live, "dock", record_topics=["image", "docking/polygon", "docking/state", "ground_truth/polygon"],
        play_topics=["image", "ground_truth/polygon"], rate=0.25)  # ~3.5 frames/s: no frame skipped on a busy machine
    stats = nodes[0].stats
    assert stats.rejected_total == 0 and stats.processed >= 0.9 * report.published / 2, stats
    offline = tmp_path / "dock_offline.mcap"
    run(scenes["docking"], offline, [], progress=False,
        processors={"docking_tracker": build_processor("docking_tracker", overrides={"initial_box": box})})
    if stats.skipped == 0:  # the same frames in: the same quadrilaterals out (seeded random numbers)
        live_quads = [[(p.x, p.y) for p in m.polygon.points] for _, m, _ in BagReader(live).ros_messages(["/dock/docking/polygon"])]
        offline_quads = [[(p.x, p.y) for p in m.polygon.points] for _, m, _ in BagReader(offline).ros_messages(["/docking/polygon"])]
        assert live_quads == offline_quads
    scores = evaluate_bags(live, config=EvaluateConfig(namespace="dock"))
    assert scores["sot"]["precision_px"] == 20 and np.isfinite(scores["sot"]["success_auc"]), scores["sot"]
    # Quality over tracker seeds (one draw of a particle filter hangs on the CPU's rounding; the median
    # does not): the offline core on the same frames, from the same loose box.
    aucs, precisions = [], []
    for seed in range(5):
        seq = open_sequence(scenes["docking"])
        r = track(seq.frames, np.array(box), DockingConfig(seed=seed), seq.count, progress=False)
        s = score_run(r, seq.gt)
        aucs.append(s["success_auc"])
        precisions.append(s["precision"])
    # the static-camera extent raised the median AUC here from 0.59 to 0.64 and moved the centre: the
    # foreground's box is 3-30 % taller than the template rectangle at the true state (the 5x5 blur, what
    # lies under the aircraft), so precision@20px fell from 1.0 to 0.63 (docs/docking_tracker.md)
    assert np.median(aucs) > 0.55, aucs
    assert np.median(precisions) > 0.5, precisions
