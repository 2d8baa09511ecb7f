"""Faults found by bench/pipeline.py, as small tests (no DDS: the shared guarded processing path).

The rejection counter behind ``/diagnostics`` is keyed by the reason text. Reasons carry numbers
(byte counts, image sizes, row counts), so a camera sending truncated frames of varying length, or
detections with a varying number of bad rows, adds one key per distinct number: the counter, and
the node's memory, grow without bound over a long run, and the top-3 reasons in /diagnostics
become one kind split many ways. ``processing.reason_key`` promises "counted by kind".
"""
from aircraft_docking_tracker.ros.processing import MessageProcessor, ProcessingStats, process_guarded


class _Refuses(MessageProcessor):
    """Refuses every input the way images.py / association_node do: a reason with numbers in it."""

    inputs = {"image": "sensor_msgs/msg/Image"}

    def __init__(self):
        self.calls = 0

    def process(self, topic, msg):
        self.calls += 1
        raise ValueError(f"data has {self.calls} bytes, a 64x48 bgr8 image with step 192 needs 9216")


def test_rejection_reasons_are_counted_by_kind_not_by_number():
    stats, processor = ProcessingStats(), _Refuses()
    for _ in range(1000):
        process_guarded(processor, "image", object(), stats)
    assert stats.rejected_total == 1000
    # one kind of fault: a handful of keys at most, not one per distinct byte count
    assert len(stats.rejected) <= 10, f"{len(stats.rejected)} distinct reason keys for one kind of fault"


def test_node_level_rejections_are_folded_too():
    stats = ProcessingStats()
    for n in range(1, 500):
        stats.reject(f"detections: {n} invalid rows (NaN, inf or size <= 0) dropped")
    assert list(stats.rejected) == ["detections: # invalid rows (NaN, inf or size <= #) dropped"]
