"""Box helpers shared by the cores (aircraft_docking_tracker.geometry)."""
import numpy as np

from aircraft_docking_tracker.geometry import boxes_hold, centres_agree


def test_boxes_hold_their_points_edges_included():
    boxes = np.array([[0, 0, 10, 10], [20, 20, 5, 5]], float)
    assert boxes_hold(boxes, np.array([10, 0])).tolist() == [True, False]          # one point for all boxes
    assert boxes_hold(boxes, np.array([[5, 5], [26, 22]])).tolist() == [True, False]
    assert not boxes_hold(boxes, np.array([np.nan, 5])).any()


def test_centres_agree_whatever_the_sizes_but_not_when_one_centre_is_outside():
    track = np.array([100, 100, 40, 20], float)                     # centre (120, 110)
    twice = [80, 90, 80, 40]                                         # the same centre, IoU 0.25
    inside_small = [115, 105, 10, 10]                                # holds (120, 110); the track holds its centre
    beside = [110, 60, 100, 60]                                      # holds the track's centre, not the reverse
    elsewhere = [300, 300, 40, 20]
    assert centres_agree([twice, inside_small, beside, elsewhere], track).tolist() == [True, True, False, False]
