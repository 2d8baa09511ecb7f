"""Entry point of ``docking_tracker_node`` and the thread defaults of every node executable
(``multi_target_tracker/executables.py`` has the detector's and the association's).

Before numpy, SciPy and OpenCV load, each compute library is given one thread unless the
environment already says how many (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``,
``MKL_NUM_THREADS``, ``OPENCV_FOR_THREADS_NUM``). A node is one process of several on the
machine (detector, tracker, recorder, the camera driver): BLAS threads that spin-wait for a core
another process holds made the docking tracker's 300-particle frames 6x slower under load
(208 ms against 32 ms, median; `make demo`'s stand track skipped 16 frames in a row there), and a
second thread bought the detectors nothing on a loaded machine. The detector's own parallelism is
its ``threads`` parameter.
"""
import os

THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM")


def one_thread_per_library() -> None:
    """Default every compute library to one thread (a variable already set is left as it is)."""
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, "1")


def docking_tracker_node(args=None):
    one_thread_per_library()
    from aircraft_docking_tracker.docking_tracker_node import main  # noqa: PLC0415

    return main(args)
