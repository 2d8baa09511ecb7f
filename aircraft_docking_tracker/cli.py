"""Command-line helpers shared by the executables that own a ROS context."""
from __future__ import annotations


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """Split ``argv`` (without the program name) into the tool's own arguments and ROS arguments.

    Everything between ``--ros-args`` and ``--`` (or the end) goes to rcl; the rest is the tool's.
    rcl's ``remove_ros_args`` would also take any ``old:=new`` outside ``--ros-args`` as a legacy
    remap rule, which swallowed options like ``mcap_play --remap image:=/cam/image``.
    """
    own, ros, inside = [], [], False
    for arg in argv:
        if arg == "--ros-args":
            inside = True
            ros.append(arg)
        elif arg == "--" and inside:
            inside = False
        elif inside:
            ros.append(arg)
        else:
            own.append(arg)
    return own, ros
