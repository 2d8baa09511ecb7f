"""Interop (issue #16, item 7): rosdep keys that exist, test plugins declared, the pip step documented."""
from __future__ import annotations

import configparser
import re
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# Keys checked against ros/rosdistro rosdep/python.yaml: each has an entry for Ubuntu 24.04 (noble,
# Jazzy's platform), either explicit or through the distribution-wide list. python3-numba is defined
# for bionic and focal only; there is no python3-mcap*, python3-motmetrics* or python3-rosbags* key.
ROSDEP_PYTHON_KEYS = {"python3-numpy", "python3-scipy", "python3-opencv", "python3-yaml", "python3-tqdm",
                      "python3-matplotlib", "python3-pytest", "python3-pytest-timeout"}
PIP_ONLY = {"mcap", "motmetrics", "numba", "rosbags"}


def requirement_names(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name = re.split(r"[<>=!~\[ ]", line, maxsplit=1)[0].lower()
            out[name] = line
    return out


def test_package_xml_uses_only_rosdep_keys_that_exist():
    root = ET.parse(REPO / "package.xml").getroot()
    keys = {e.text for tag in ("depend", "exec_depend", "test_depend", "build_depend") for e in root.iter(tag)}
    python_keys = {k for k in keys if k.startswith("python3-")}
    assert python_keys <= ROSDEP_PYTHON_KEYS, f"no such rosdep key: {sorted(python_keys - ROSDEP_PYTHON_KEYS)}"
    assert not [k for k in keys if k.endswith("-pip")]


def test_pytest_plugins_that_pytest_ini_needs_are_declared():
    ini = configparser.ConfigParser()
    ini.read(REPO / "pytest.ini")
    if "--timeout" in ini["pytest"].get("addopts", ""):
        assert "pytest-timeout" in requirement_names(REPO / "requirements-test.txt")
        test_deps = {e.text for e in ET.parse(REPO / "package.xml").getroot().iter("test_depend")}
        assert "python3-pytest-timeout" in test_deps


def test_the_pip_step_lists_what_rosdep_cannot_install_with_the_same_versions():
    pip_only = requirement_names(REPO / "requirements-pip-only.txt")
    assert set(pip_only) == PIP_ONLY
    declared = requirement_names(REPO / "requirements.txt") | requirement_names(REPO / "requirements-test.txt")
    for name, line in pip_only.items():
        assert declared[name] == line, f"{name}: {line} here, {declared[name]} in requirements*.txt"
    readme = (REPO / "README.md").read_text()
    assert "requirements-pip-only.txt" in readme and "rosdep install" in readme
