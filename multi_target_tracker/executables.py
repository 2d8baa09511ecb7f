"""Entry points of ``detector_node`` and ``association_node``: one compute thread per library before
numpy / OpenCV load (``aircraft_docking_tracker/executables.py`` says why)."""
from aircraft_docking_tracker.executables import one_thread_per_library


def detector_node(args=None):
    one_thread_per_library()
    from multi_target_tracker.detector_node import main  # noqa: PLC0415 - after the thread defaults

    return main(args)


def association_node(args=None):
    one_thread_per_library()
    from multi_target_tracker.association_node import main  # noqa: PLC0415

    return main(args)
