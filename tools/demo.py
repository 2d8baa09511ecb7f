"""`make demo`: a docking stand camera and a UAV pass, through the three nodes live over ROS 2.

1. makes (or reuses) two scenario bags: a docking stand camera and a UAV pass, with ground truth;
2. starts the nodes as separate processes, the way `ros2 run` does, one camera per namespace:
   /stand: detector_node -> docking_tracker_node, started from an operator's box (the first
           frame's ground truth stands in for the click), re-acquiring from detections if lost;
   /uav:   detector_node -> association_node;
   parameters from config/stand_camera.yaml and config/uav_camera.yaml;
3. records every topic of both cameras and /diagnostics with mcap_record;
4. plays both bags at once with mcap_play, remapped into the namespaces;
5. stops everything with SIGINT, scores the recording against the ground truth with the
   evaluation harness, prints a summary and writes a report folder (tables, plots, image strips).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from aircraft_docking_tracker.scenarios.uav import UAV_SETUP_GROUND_RESOLUTION  # noqa: E402
CAMERAS = {
    # namespace: (scenario kind, seed, scenario options, nodes, set-up file, topics to play, rate factor)
    # stand: seed 3 (the docking tracker learns nothing offline; the docking cascade saw this scene in
    # training and gives the start box, re-acquires a lost aircraft and may override a track: the live
    # track scores what the offline core does from the ground truth's loose box, 0.71); UAV: seed 106,
    # held out from its cascade
    "stand": ("docking", 3, {"frames": 210, "fps": 14.0, "width": 640, "height": 480},
              ["detector_node", "docking_tracker_node"], "stand_camera.yaml",
              ["image", "ground_truth/polygon", "ground_truth/nose", "ground_truth/stand", "ground_truth/guidance"], 1.0),
    # the UAV camera flies at the height its set-up is made for (UAV_SETUP_GROUND_RESOLUTION: 3x lower
    # than the scene's default, vehicles >= 33 px; config/uav_camera.yaml). Played at 0.5x (5 frames/s);
    # the detector (about 5.6 frames/s alone, bench/uav_detector.py) does not always keep up beside the
    # stand camera on a shared machine: stale frames are skipped, counted and scored as misses
    "uav": ("uav", 106, {"frames": 80, "fps": 10.0, "width": 640, "height": 480,
                         "ground_resolution": UAV_SETUP_GROUND_RESOLUTION},
            ["detector_node", "association_node"], "uav_camera.yaml", ["image", "ground_truth"], 0.5),
}


def make_bags(folder: Path) -> dict[str, Path]:
    """Scenario bags, remade only when their recipe changed."""
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig
    from aircraft_docking_tracker.scenarios.make_scenario import write_docking_bag, write_uav_bag
    from aircraft_docking_tracker.scenarios.uav import UavScene, UavSceneConfig

    folder.mkdir(parents=True, exist_ok=True)
    bags = {}
    for namespace, (kind, seed, options, *_rest) in CAMERAS.items():
        path = folder / f"{kind}_seed{seed}.mcap"
        recipe = folder / f"{kind}_seed{seed}.json"
        wanted = json.dumps({"kind": kind, "seed": seed, **options}, sort_keys=True)
        if not (path.exists() and recipe.exists() and recipe.read_text() == wanted):
            print(f"demo: making the {kind} scenario bag ({options['frames']} frames)...", flush=True)
            if kind == "docking":
                write_docking_bag(DockingScene(DockingSceneConfig(**options), seed=seed), path, overwrite=True)
            else:
                write_uav_bag(UavScene(UavSceneConfig(**options), seed=seed), path, overwrite=True)
            recipe.write_text(wanted)
        bags[namespace] = path
    return bags


def run_live(bags: dict[str, Path], out: Path, rate: float) -> Path:
    from aircraft_docking_tracker.config import package_config_dir
    from aircraft_docking_tracker.processes import NodeProcess, wait_until

    logs = out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    recording = out / "recording"
    if recording.exists():
        for f in recording.iterdir():
            f.unlink()
        recording.rmdir()
    config_dir = package_config_dir()
    # the operator's start box, and the stand's calibration (config/stands/demo_stand.yaml: this scene's stand,
    # written by make_scenario --stand-file) for the docking guidance
    stand_setup = {"initial_box": first_box(bags["stand"]), "guidance.stand_file": "demo_stand.yaml"}
    nodes = [NodeProcess(exe, namespace=ns, params_file=config_dir / setup, log_path=logs / f"{ns}_{exe}.log",
                         parameters=stand_setup if exe == "docking_tracker_node" else {})
             for ns, (_, _, _, exes, setup, _, _) in CAMERAS.items() for exe in exes]
    recorder = NodeProcess("mcap_record", args=["-a", "-o", recording, "--exclude", "^/(rosout|parameter_events)$"],
                           log_path=logs / "mcap_record.log")
    print(f"demo: starting {len(nodes)} nodes and the recorder (logs in {logs})", flush=True)
    for node in nodes:
        node.start()
    recorder.start()
    try:
        expected = [f"/{ns}/{t}" for ns, (_, _, _, exes, _, _, _) in CAMERAS.items()
                    for t in (["docking/polygon"] if "docking_tracker_node" in exes else ["tracks"])]
        up = wait_until(lambda: all(f"recording {t}" in (logs / "mcap_record.log").read_text() for t in expected), 60)
        if not up:
            raise RuntimeError(f"nodes did not come up in 60 s; see {logs}")
        players = [NodeProcess("mcap_play", args=[bags[ns], "--rate", rate * factor, "--topics", *topics,
                                                  "--remap", *[f"{t}:=/{ns}/{t}" for t in topics],
                                                  "--wait-for-subscribers", "30", "--delay", "2"],
                               log_path=logs / f"mcap_play_{ns}.log")
                   for ns, (*_, topics, factor) in CAMERAS.items()]
        print("demo: playing both bags live...", flush=True)
        for player in players:
            player.start()
        for player in players:
            player.wait(600)
        time.sleep(2.0)  # the last frames through the nodes
    finally:
        recorder.stop()
        for node in nodes:
            node.stop()
    failed = [n for n in nodes if n.process.returncode not in (0, None)]
    if failed:
        print(f"demo: warning: {[n.executable for n in failed]} exited with errors; see {logs}", file=sys.stderr)
    return recording


def first_box(bag: Path) -> list[float]:
    """The axis-aligned box of the first ground-truth polygon: what an operator would mark."""
    from aircraft_docking_tracker.io.bag import BagReader

    for _, msg, _ in BagReader(bag).ros_messages(["ground_truth/polygon"]):
        xs, ys = [p.x for p in msg.polygon.points], [p.y for p in msg.polygon.points]
        return [min(xs), min(ys), max(xs) - min(xs), max(ys) - min(ys)]
    raise RuntimeError(f"{bag} has no ground_truth/polygon")


def diagnostics_summary(recording: Path) -> dict:
    """The last /diagnostics status of every node: processed, skipped, rejected."""
    from aircraft_docking_tracker.io.bag import BagReader

    last = {}
    for _, msg, _ in BagReader(recording).ros_messages(["/diagnostics"]):
        for status in msg.status:
            last[status.hardware_id] = {kv.key: kv.value for kv in status.values}
    return last


# (the nodes' stamp latency is left out: replayed bags carry their recording's stamps)
DIAGNOSTIC_COLUMNS = [("received", "received"), ("processed", "processed"), ("skipped", "skipped"),
                      ("rejected", "rejected"), ("processing_ms_p50", "proc. p50 ms"),
                      ("processing_ms_p95", "proc. p95 ms"), ("processing_ms_max", "proc. max ms")]
ROLES = {"stand": "docking stand camera: detector -> docking tracker",
         "uav": "UAV camera: detector -> association"}


def summary_markdown(results: dict, recording: Path) -> str:
    """summary.md: per camera, a table per metric family; then each node's last /diagnostics."""
    from aircraft_docking_tracker.evaluation.report import format_markdown, markdown_table

    lines = ["# Demo report", "", f"Recording: `{recording}`. Plots and annotated strips: one folder per camera.", ""]
    for namespace in CAMERAS:
        lines += [f"## /{namespace} ({ROLES.get(namespace, '')})", "", format_markdown({namespace: results[namespace]}), ""]
    diagnostics = results.get("diagnostics") or {}
    lines += ["## Nodes (their last /diagnostics)", ""]
    if diagnostics:
        body = [[node] + [values.get(key, "-") for key, _ in DIAGNOSTIC_COLUMNS]
                for node, values in sorted(diagnostics.items())]
        lines.append(markdown_table(["node"] + [title for _, title in DIAGNOSTIC_COLUMNS], body))
    else:
        lines.append("(no /diagnostics in the recording)")
    return "\n".join(lines) + "\n"


def report(recording: Path, bags: dict[str, Path], out: Path) -> dict:
    from aircraft_docking_tracker.evaluation.evaluate import EvaluateConfig, evaluate_bags, write_plots, write_strip
    from aircraft_docking_tracker.evaluation.report import write_json

    folder = out / "report"
    folder.mkdir(parents=True, exist_ok=True)
    results = {}
    for namespace in CAMERAS:
        scores = evaluate_bags(recording, config=EvaluateConfig(namespace=namespace))
        results[namespace] = scores
        sub = folder / namespace
        sub.mkdir(exist_ok=True)
        write_plots({namespace: scores}, sub)
        write_strip(recording, None, sub / "strip.png", namespace=namespace)
    results["diagnostics"] = diagnostics_summary(recording)
    write_json(folder / "summary.json", results)
    (folder / "summary.md").write_text(summary_markdown(results, recording))
    return results


def print_summary(results: dict, out: Path) -> None:
    stand, uav = results["stand"], results["uav"]
    sot, mot, det = stand.get("sot", {}), uav.get("mot", {}), uav.get("detection", {})
    print("\n=== demo summary ===")
    print(f"stand camera (/stand, docking tracker): {sot.get('scored_frames', '?')} frames, "
          f"success AUC {sot.get('success_auc', float('nan')):.3f}, precision@20px {sot.get('precision', float('nan')):.3f}")
    guidance = stand.get("guidance", {})
    if guidance:
        stop = (f"STOP first shown {guidance['stop_at_m']:.2f} m before the mark" if not guidance["stop_missed"]
                else "STOP never shown")
        print(f"  docking guidance: within the last 15 m lateral error p95 {guidance['lateral_near_p95']:.2f} m, "
              f"distance error p95 {guidance['distance_near_p95']:.2f} m; {stop}; states right on "
              f"{100 * guidance['state_accuracy']:.0f} % of frames")
    print(f"UAV camera (/uav, detector + association): MOTA {mot.get('mota', float('nan')):.3f}, "
          f"IDF1 {mot.get('idf1', float('nan')):.3f}, ID switches {mot.get('num_switches', '?')}, "
          f"detection rate {det.get('detection_rate', float('nan')):.3f}, false alarms {det.get('false_alarm_rate', float('nan')):.3f}")
    for namespace in CAMERAS:
        for topic, speed in results[namespace].get("speed", {}).items():
            if isinstance(speed, dict) and "rate_hz" in speed:
                print(f"  /{namespace}/{topic}: {speed['count']} messages, {speed['rate_hz']:.1f} per second")
    # Per-node figures from the nodes' own /diagnostics (end-to-end latency with wall-clock stamps
    # is measured by `make bench`, bench/pipeline.py: recorder log times lag when the CPU is busy).
    for node, values in sorted(results["diagnostics"].items()):
        of = f" per {values['processing_topic']}" if "processing_topic" in values else ""
        print(f"  {node}: {values.get('processed')} messages processed, {values.get('skipped')} skipped "
              f"(keep-newest), {values.get('rejected')} rejected; processing{of} p50 {values.get('processing_ms_p50')} "
              f"ms, max {values.get('processing_ms_max')} ms")
    print(f"report: {out / 'report'} (summary.md, summary.json, plots and strips per camera)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="out/demo", help="output folder (bags, recording, report)")
    parser.add_argument("--rate", default="1.0", help="playback rate of the scenario bags")
    args = parser.parse_args()
    out = Path(args.out)
    started = time.monotonic()
    bags = make_bags(out / "bags")
    recording = run_live(bags, out, float(args.rate))
    results = report(recording, bags, out)
    print_summary(results, out)
    print(f"demo: done in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
