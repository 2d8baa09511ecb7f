"""The OpenCV cascade backend on a real third-party Haar cascade (cars.xml + video1.avi)."""
import cv2
import numpy as np
import pytest

from conftest import require_data
from multi_target_tracker import opencv_backend
from multi_target_tracker.detector import Detector, DetectorConfig, DetectorError
from multi_target_tracker.opencv_backend import OpenCVCascade, OpenCVCascadeError, OpenCVCascadeUnavailable


def _frames(n):
    cap = cv2.VideoCapture(str(require_data("cascades/video1.avi")))
    out = []
    while len(out) < n:
        ok, frame = cap.read()
        if not ok:
            break
        out.append(frame)
    return out


def test_cars_xml_finds_cars_on_video1():
    cascade = OpenCVCascade(require_data("cascades/cars.xml"))
    assert cascade.window == (20, 20)
    frames = _frames(20)
    assert len(frames) == 20
    counts = []
    for frame in frames:
        boxes, scores = cascade.detect(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY), 1.1, 2)
        assert boxes.shape[1] == 4 and len(scores) == len(boxes)
        assert (boxes[:, 2] >= 20).all() and (boxes[:, 0] + boxes[:, 2] <= 320).all()
        counts.append(len(boxes))
    assert sum(counts) >= 20          # freeway traffic: cars in most frames
    det = Detector(DetectorConfig(backend="opencv", model=str(require_data("cascades/cars.xml")),
                                  scale_factor=1.1, min_neighbors=2, min_size=30, roi=[0, 100, 320, 140]))
    table = det.detect(frames[0])
    assert (table["y"] >= 100).all() and (table["h"] >= 30).all()
    table_all = Detector(DetectorConfig(backend="opencv", model=str(require_data("cascades/cars.xml")),
                                        scale_factor=1.1, min_neighbors=2)).detect(frames[0])
    assert len(table_all) >= len(table)


def test_missing_cascade_classifier_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.delattr(opencv_backend.cv2, "CascadeClassifier")
    with pytest.raises(OpenCVCascadeUnavailable, match="CascadeClassifier"):
        OpenCVCascade(tmp_path / "x.xml")


def test_bad_xml(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<opencv_storage><cascade><nothing/></cascade></opencv_storage>")
    with pytest.raises(OpenCVCascadeError):
        OpenCVCascade(bad)
    with pytest.raises(DetectorError):
        Detector(DetectorConfig(backend="opencv", model=str(tmp_path / "missing.xml")))
    with pytest.raises(OpenCVCascadeError):
        OpenCVCascade(require_data("cascades/cars.xml")).detect(np.zeros((10, 10), np.float32))
