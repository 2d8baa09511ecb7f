"""Packaging honesty: entry points resolve, package.xml declares what the code imports."""
import importlib
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from setup_entry_points import console_scripts

REPO = Path(__file__).resolve().parent.parent
ROS_PACKAGES = {"rclpy", "builtin_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs", "visualization_msgs",
                "diagnostic_msgs", "rosgraph_msgs", "rcl_interfaces", "ament_index_python"}


@pytest.mark.parametrize("name, target", sorted(console_scripts().items()))
def test_every_console_script_has_a_main(name, target):
    module, func = target.split(":")
    assert callable(getattr(importlib.import_module(module), func)), name


def test_package_xml_declares_every_ros_package_the_code_imports():
    declared = {e.text for e in ET.parse(REPO / "package.xml").getroot().iter("exec_depend")}
    used = set()
    for path in list((REPO / "aircraft_docking_tracker").rglob("*.py")) + list((REPO / "multi_target_tracker").rglob("*.py")):
        for match in re.finditer(r"^\s*(?:from|import)\s+([a-z_]+)", path.read_text(), flags=re.M):
            if match.group(1) in ROS_PACKAGES:
                used.add(match.group(1))
    assert used <= declared, f"package.xml lacks exec_depend {sorted(used - declared)}"
    assert ET.parse(REPO / "package.xml").getroot().find("export/build_type").text == "ament_python"


def test_algorithm_cores_import_no_ros():
    cores = ["affine_group", "appearance", "ispf", "docking"]
    mt_cores = ["features", "cascade", "detector", "kalman", "association"]
    paths = [REPO / "aircraft_docking_tracker" / f"{c}.py" for c in cores]
    paths += [REPO / "multi_target_tracker" / f"{c}.py" for c in mt_cores]
    paths += list((REPO / "aircraft_docking_tracker" / "evaluation").glob("*_metrics.py"))
    for path in paths:
        text = path.read_text()
        bad = [m.group(1) for m in re.finditer(r"^\s*(?:from|import)\s+([a-z_]+)", text, flags=re.M) if m.group(1) in ROS_PACKAGES]
        assert not bad, f"{path.name} imports ROS: {bad}"
