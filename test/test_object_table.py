"""Object tables as PointCloud2: round trip, typed fields, foreign layouts, malformed clouds."""
import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2, PointField

from aircraft_docking_tracker.object_table import (
    DETECTION_DTYPE, TRACK_DTYPE, ObjectTableError, cloud_to_table, records, table_to_cloud)


def test_detection_round_trip_keeps_names_types_values():
    table = np.array([(1.5, 2.0, 10.0, 20.0, 0.9, 3), (100.0, 50.0, 8.0, 8.0, 0.1, 0)], dtype=DETECTION_DTYPE)
    msg = table_to_cloud(table)
    assert [f.name for f in msg.fields] == list(DETECTION_DTYPE.names)
    assert [f.datatype for f in msg.fields] == [7, 7, 7, 7, 7, 5]
    assert (msg.width, msg.height, msg.point_step) == (2, 1, 24)
    back = cloud_to_table(msg, DETECTION_DTYPE)
    np.testing.assert_array_equal(back, table)
    assert records(back)[0]["class_id"] == 3


def test_empty_table_and_track_dtype():
    msg = table_to_cloud(np.zeros(0, TRACK_DTYPE))
    assert msg.width == 0 and len(cloud_to_table(msg, TRACK_DTYPE)) == 0


def test_foreign_layout_with_padding_and_big_endian():
    """A cloud written by someone else: padded points, other field order, big-endian."""
    msg = PointCloud2()
    msg.height, msg.width, msg.point_step, msg.is_bigendian = 1, 2, 32, True
    msg.fields = [PointField(name=n, offset=o, datatype=d, count=1) for n, o, d in
                  [("score", 0, 8), ("x", 8, 7), ("y", 12, 7), ("w", 16, 7), ("h", 20, 7), ("class_id", 24, 5)]]
    rows = np.zeros(2, np.dtype({"names": ["score", "x", "y", "w", "h", "class_id"],
                                 "formats": [">f8", ">f4", ">f4", ">f4", ">f4", ">i4"],
                                 "offsets": [0, 8, 12, 16, 20, 24], "itemsize": 32}))
    rows["x"], rows["score"], rows["class_id"] = [1, 2], [0.5, 0.25], [7, 8]
    msg.data = rows.tobytes()
    table = cloud_to_table(msg, DETECTION_DTYPE)
    assert table["x"].tolist() == [1.0, 2.0] and table["class_id"].tolist() == [7, 8]
    assert table["score"].tolist() == [0.5, 0.25]


def test_malformed_clouds_are_refused():
    msg = table_to_cloud(np.zeros(3, DETECTION_DTYPE))
    short = PointCloud2(height=1, width=3, point_step=msg.point_step, fields=msg.fields, data=bytes(msg.data)[:10])
    with pytest.raises(ObjectTableError, match="need"):
        cloud_to_table(short)
    with pytest.raises(ObjectTableError, match="lacks field"):
        cloud_to_table(msg, TRACK_DTYPE)
    with pytest.raises(ObjectTableError, match="structured"):
        table_to_cloud(np.zeros(3))
