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


def test_the_node_executables_default_each_compute_library_to_one_thread(monkeypatch):
    """The nodes' entry points set the thread defaults before numpy / OpenCV load (importing the entry
    module loads neither), and leave a variable the user set alone."""
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415

    from aircraft_docking_tracker import executables  # noqa: PLC0415

    for name, package in (("detector_node", "multi_target_tracker"), ("association_node", "multi_target_tracker"),
                          ("docking_tracker_node", "aircraft_docking_tracker")):
        assert console_scripts()[name] == f"{package}.executables:{name}"
    probe = ("import sys, aircraft_docking_tracker.executables, multi_target_tracker.executables; "
             "print(sorted({'numpy', 'cv2', 'scipy'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip() == "[]", out
    for name in executables.THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    executables.one_thread_per_library()
    import os  # noqa: PLC0415

    assert os.environ["OPENBLAS_NUM_THREADS"] == "1" and os.environ["OPENCV_FOR_THREADS_NUM"] == "1"
    assert os.environ["OMP_NUM_THREADS"] == "3"


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
    shared = ["geometry"]    # config, object_table and images reach ROS packages inside functions
    mt_cores = ["features", "cascade", "detector", "kalman", "association"]
    paths = sorted((REPO / "aircraft_docking_tracker" / "docking").glob("*.py"))
    paths += [REPO / "aircraft_docking_tracker" / f"{c}.py" for c in shared]
    paths += [REPO / "multi_target_tracker" / f"{c}.py" for c in mt_cores]
    paths += list((REPO / "aircraft_docking_tracker" / "evaluation").glob("*_metrics.py"))
    for path in paths:
        text = path.read_text()
        bad = [m.group(1) for m in re.finditer(r"^\s*(?:from|import)\s+([a-z_]+)", text, flags=re.M) if m.group(1) in ROS_PACKAGES]
        assert not bad, f"{path.name} imports ROS: {bad}"


def test_docking_cores_import_only_shared_helpers():
    """The docking cores depend on the small shared helpers (config, geometry, tables) and on each other,
    never on the ROS layer, the files, the evaluation, the scenarios or a tool."""
    allowed = {"docking", "config", "geometry", "object_table", "images"}
    for path in sorted((REPO / "aircraft_docking_tracker" / "docking").glob("*.py")):
        text = path.read_text()
        relative = re.findall(r"^\s*from (\.+)(\w*)", text, flags=re.M)
        absolute = re.findall(r"^\s*(?:from|import) aircraft_docking_tracker\.(\w+)", text, flags=re.M)
        used = {name or "docking" for dots, name in relative if dots == ".."} | set(absolute)
        used |= {"docking" for dots, _ in relative if dots == "."}
        assert used <= allowed, f"{path.name} imports {sorted(used - allowed)}"


@pytest.mark.slow
def test_colcon_build_installs_what_ros2_run_and_the_nodes_look_for(tmp_path):
    """``colcon build`` (colcon-ros, as on a Jazzy install) of this one package: every console script in
    ``lib/<package>/`` (where ``ros2 run`` looks), the ament index marker and ``package.xml`` in
    ``share/``, the configs in ``share/<package>/config`` (where the nodes read them), the models beside
    the code; and an installed node starts from that layout."""
    import os
    import subprocess
    import sys

    pytest.importorskip("colcon_ros", reason="colcon-ros not installed (requirements-test.txt)")
    build = subprocess.run([sys.executable, "-m", "colcon", "--log-base", str(tmp_path / "log"), "build",
                            "--paths", str(REPO), "--build-base", str(tmp_path / "build"),
                            "--install-base", str(tmp_path / "install")],
                           cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    prefix = tmp_path / "install" / "aircraft_docking_tracker"
    assert (prefix / "share/ament_index/resource_index/packages/aircraft_docking_tracker").exists()
    assert (prefix / "share/aircraft_docking_tracker/package.xml").read_text() == (REPO / "package.xml").read_text()
    assert {p.name for p in (prefix / "share/aircraft_docking_tracker/config").glob("*.yaml")} == \
        {p.name for p in (REPO / "config").glob("*.yaml")}
    assert {p.name for p in (prefix / "lib/aircraft_docking_tracker").iterdir()} == set(console_scripts())
    site = next(prefix.glob("lib/python3*/site-packages"))
    for kind in ("*.json", "*.onnx"):      # the patch network's ONNX graph beside its JSON header
        assert {p.name for p in (site / "multi_target_tracker/models").glob(kind)} == \
            {p.name for p in (REPO / "multi_target_tracker/models").glob(kind)}
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]),
               AMENT_PREFIX_PATH=os.pathsep.join([str(prefix), os.environ.get("AMENT_PREFIX_PATH", "")]))
    probe = subprocess.run([sys.executable, "-c", "import aircraft_docking_tracker as a, multi_target_tracker as m;"
                            "from ament_index_python.packages import get_package_share_directory as g;"
                            "from aircraft_docking_tracker.config import package_config_dir as c;"
                            "print(a.__file__, m.__file__, g('aircraft_docking_tracker'), c())"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.split() == [str(site / "aircraft_docking_tracker/__init__.py"),
                                    str(site / "multi_target_tracker/__init__.py"),
                                    str(prefix / "share/aircraft_docking_tracker"),
                                    str(prefix / "share/aircraft_docking_tracker/config")]
    node = subprocess.run([sys.executable, str(prefix / "lib/aircraft_docking_tracker/docking_tracker_node"), "--help"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert node.returncode == 0 and "initial_box" in node.stdout, node.stdout + node.stderr
