"""Docking cores (pure: numpy, scipy, OpenCV; no ROS): the affine group, the appearance model, ISPF,
the static-camera background, the start / loss / re-acquisition logic around the filter."""
