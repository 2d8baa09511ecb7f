"""bench/multihost.py: images between hosts over ROS 2's DDS (UDP), and cameras per compute host.

    python bench/multihost.py [--quick]          # root and iproute2 needed; loss: tc netem or nftables

Hosts are Linux network namespaces on one emulated Ethernet segment (aircraft_docking_tracker/netns.py:
10.231.x.x inside the namespaces only, a private /dev/shm per host, so every byte crosses UDP).

1. **transfer**: a camera host publishes sensor_msgs/Image (bgr8) at 640x480 and 1280x720, 10 and 30 Hz,
   stamped with the clock at publish; a compute host subscribes (sensor-data QoS, best effort, as the
   nodes do) and times each arrival: images/s, lost, latency p50/p95, the subscriber's CPU per image.
   With packet loss injected into the compute host (every lost packet, i.e. IP fragment, counts);
   side by side: the shipped profile (config/fastdds_multihost.xml: datagrams within one 1500-byte
   MTU) against 64 KB datagrams (IP-fragmented), and best effort against reliable QoS.
2. **link drop**: the camera host's link down for 5 s mid-stream at 640x480 10 Hz: the time from the
   link coming back to the first image received (repeated; mean and worst).
3. **cameras per compute host**: CPU per frame of each node's processor at its defaults (offline,
   the same code the nodes run) plus the measured transport CPU per image, turned into how many
   cameras this machine's cores serve at 10 and 30 Hz.

Writes bench/results/multihost.json and .md, bench/plots/multihost_*.png. The machine is shared and
has 2 cores: read the numbers as orders of magnitude and the side-by-side ratios.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "bench" / "results"
PLOTS = ROOT / "bench" / "plots"
SIZES = {"640x480": (640, 480), "1280x720": (1280, 720)}


# ------------------------------------------------------------------------------ roles on a host
def role_publish(size: str, hz: float, seconds: float, reliable: bool, out: str) -> None:
    """Camera host: wait for a subscriber, then publish ``seconds`` of images at ``hz``."""
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSProfile, qos_profile_sensor_data  # noqa: PLC0415
    from sensor_msgs.msg import Image  # noqa: PLC0415

    from aircraft_docking_tracker.io.bag import ns_to_stamp  # noqa: PLC0415

    w, h = SIZES[size]
    rclpy.init()
    node = rclpy.create_node("bench_camera")
    qos = QoSProfile(depth=10) if reliable else qos_profile_sensor_data
    pub = node.create_publisher(Image, "/bench/image", qos)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.5)  # discovery settles on both sides
    rng = np.random.default_rng(0)
    msg = Image(height=h, width=w, encoding="bgr8", step=w * 3, data=rng.integers(0, 255, w * h * 3, np.uint8).tobytes())
    period, start, sent = 1.0 / hz, time.monotonic(), 0
    started_ns = time.time_ns()
    while time.monotonic() - start < seconds:
        target = start + sent * period
        time.sleep(max(0.0, target - time.monotonic()))
        msg.header.stamp = ns_to_stamp(time.time_ns())
        msg.header.frame_id = str(sent)
        pub.publish(msg)
        sent += 1
    Path(out).write_text(json.dumps({"published": sent, "started_ns": started_ns, "ended_ns": time.time_ns()}))
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()


def role_subscribe(reliable: bool, seconds: float, out: str) -> None:
    """Compute host: time every image's arrival (receive - header stamp) until ``seconds`` pass."""
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSProfile, qos_profile_sensor_data  # noqa: PLC0415
    from sensor_msgs.msg import Image  # noqa: PLC0415

    rclpy.init()
    node = rclpy.create_node("bench_compute")
    arrivals = []

    def on_image(msg):
        now = time.time_ns()
        arrivals.append((now, msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec, int(msg.header.frame_id)))

    qos = QoSProfile(depth=10) if reliable else qos_profile_sensor_data
    node.create_subscription(Image, "/bench/image", on_image, qos)
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu_s = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    Path(out).write_text(json.dumps({"arrivals": arrivals, "cpu_s": cpu_s}))
    node.destroy_node()
    rclpy.shutdown()


# ------------------------------------------------------------------------------ controller
@dataclass
class Cell:
    size: str
    hz: float
    loss_pct: float = 0.0
    reliable: bool = False
    profile: str = "shipped"          # shipped (MTU datagrams) or 64k (IP-fragmented datagrams)
    link_drop_s: float = 0.0


def percentile(values, q):
    return round(float(np.percentile(values, q)), 1) if len(values) else None


def profile_path(name: str, workdir: Path) -> Path:
    shipped = ROOT / "config" / "fastdds_multihost.xml"
    if name == "shipped":
        return shipped
    text = shipped.read_text().replace("<maxMessageSize>1472</maxMessageSize>", "<maxMessageSize>65500</maxMessageSize>")
    path = workdir / "fastdds_64k.xml"
    path.write_text(text)
    return path


def run_cell(net, camera, compute, cell: Cell, seconds: float, workdir: Path) -> dict:
    env = dict(os.environ, **net.ros_env(profile=profile_path(cell.profile, workdir)))
    pub_out, sub_out = workdir / "pub.json", workdir / "sub.json"
    for f in (pub_out, sub_out):
        f.unlink(missing_ok=True)
    me = [sys.executable, str(Path(__file__).resolve())]
    rel = ["--reliable"] if cell.reliable else []
    listen_s = seconds + 8.0
    sub = subprocess.Popen([*compute.prefix, *me, "--role", "subscribe", "--seconds", str(listen_s), "--out", str(sub_out),
                            *rel], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1.0)
    pub = subprocess.Popen([*camera.prefix, *me, "--role", "publish", "--size", cell.size, "--hz", str(cell.hz),
                            "--seconds", str(seconds), "--out", str(pub_out), *rel], env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    mechanism = None
    link_up_ns = None
    try:
        if cell.loss_pct > 0:
            mechanism = net.impair(compute, loss_pct=cell.loss_pct)
        if cell.link_drop_s > 0:
            time.sleep(2.5 + 3.0)  # discovery, settling, then 3 s of images
            net.link(camera, up=False)
            time.sleep(cell.link_drop_s)
            net.link(camera, up=True)
            link_up_ns = time.time_ns()
        pub.wait(timeout=seconds + 60)
        sub.wait(timeout=listen_s + 60)
    finally:
        for proc in (pub, sub):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        net.clear_impairment(compute)
        net.link(camera, up=True)
    sent = json.loads(pub_out.read_text())
    got = json.loads(sub_out.read_text())
    arrivals = [a for a in got["arrivals"] if a[0] >= sent["started_ns"]]
    latencies = [(r - s) / 1e6 for r, s, _ in arrivals]
    span_s = (sent["ended_ns"] - sent["started_ns"]) / 1e9
    row = {"size": cell.size, "hz": cell.hz, "loss_pct": cell.loss_pct, "qos": "reliable" if cell.reliable else "best effort",
           "datagrams": "1472 B (MTU)" if cell.profile == "shipped" else "64 KB (IP-fragmented)",
           "published": sent["published"], "received": len(arrivals),
           "lost": sent["published"] - len({a[2] for a in arrivals}),
           "images_per_s": round(len(arrivals) / span_s, 1) if span_s > 0 else 0.0,
           "p50_ms": percentile(latencies, 50), "p95_ms": percentile(latencies, 95),
           "cpu_ms_per_image": round(1e3 * got["cpu_s"] / len(arrivals), 2) if arrivals else None,
           "loss_by": mechanism}
    if link_up_ns is not None:
        after = [r for r, _, _ in arrivals if r >= link_up_ns]
        row["link_drop_s"] = cell.link_drop_s
        row["recovery_s"] = round((after[0] - link_up_ns) / 1e9, 2) if after else None
    print(json.dumps(row), flush=True)
    return row


def transfer_cells(quick: bool) -> list[Cell]:
    cells = []
    losses = (0.0, 0.01, 0.1) if quick else (0.0, 0.01, 0.1, 1.0)
    for size in SIZES:
        for hz in (10, 30):
            cells += [Cell(size, hz, loss) for loss in losses]
    # side by side at 640x480 30 Hz: fragment handling, then reliable QoS under loss
    cells += [Cell("640x480", 30, loss, profile="64k") for loss in ((0.0, 0.1) if quick else (0.0, 0.1, 1.0))]
    cells += [Cell("640x480", 30, loss, reliable=True) for loss in (0.1, 1.0)]
    return cells


def _cpu_ms(feed, messages) -> dict:
    """CPU time (this process, all threads) of ``feed(msg)`` per message: mean (what capacity
    needs: the docking tracker's subspace updates make some frames far dearer) and median."""
    costs = []
    for msg in messages:
        t0 = time.process_time()
        feed(msg)
        costs.append(1e3 * (time.process_time() - t0))
    return {"mean": round(float(np.mean(costs)), 2), "median": round(float(np.median(costs)), 2)}


def node_costs(frames: int) -> dict:
    """CPU ms per frame of each node's processor at its defaults, on rendered docking frames."""
    from aircraft_docking_tracker.offline import OfflineRun, build_processor  # noqa: PLC0415
    from aircraft_docking_tracker.images import numpy_to_image  # noqa: PLC0415
    from aircraft_docking_tracker.io.bag import ns_to_stamp  # noqa: PLC0415
    from aircraft_docking_tracker.scenarios.docking import DockingScene, DockingSceneConfig  # noqa: PLC0415

    out = {}
    for size, (w, h) in SIZES.items():
        scene = DockingScene(DockingSceneConfig(frames=frames, width=w, height=h), seed=4)
        images, box = [], None
        for frame in scene.frames():
            msg = numpy_to_image(frame.image, "bgr8")
            msg.header.stamp = ns_to_stamp(frame.stamp_ns)
            images.append(msg)
            if box is None:
                xs, ys = frame.quad[:, 0], frame.quad[:, 1]
                box = [float(xs.min()), float(ys.min()), float(xs.max() - xs.min()), float(ys.max() - ys.min())]
        for name, overrides in (("detector", None), ("docking_tracker", {"initial_box": box})):
            runner = OfflineRun({name: build_processor(name, overrides=overrides)})
            runner.feed("image", images[0])  # warm-up (model load, compilation)
            out.setdefault(size, {})[name] = _cpu_ms(lambda m, r=runner: r.feed("image", m), images[1:])
        # association: fed the detector's outputs
        det = OfflineRun({"detector": build_processor("detector")})
        dets = [m for msg in images for t, m in det.feed("image", msg) if t == "detections"]
        assoc = OfflineRun({"association": build_processor("association")})
        out[size]["association"] = _cpu_ms(lambda m: assoc.feed("detections", m), dets)
    return out


def cameras_per_host(costs: dict, transfer: list[dict], cores: int) -> list[dict]:
    rows = []
    for size in SIZES:
        transport = [r["cpu_ms_per_image"] for r in transfer if r["size"] == size and r["loss_pct"] == 0
                     and r["qos"] == "best effort" and r["datagrams"].startswith("1472") and r["cpu_ms_per_image"]]
        transport_ms = float(np.median(transport)) if transport else 0.0
        c = {name: cost["mean"] for name, cost in costs[size].items()}
        setups = {"docking stand (docking tracker)": c["docking_tracker"],
                  "detector -> association": c["detector"] + c["association"],
                  "detector -> association + docking tracker": c["detector"] + c["association"] + c["docking_tracker"]}
        for setup, node_ms in setups.items():
            # each node process receives its own copy of the image: transport cost per subscribing node
            receivers = 1 if setup.startswith("docking stand") else (1 if "+" not in setup else 2)
            per_frame = node_ms + receivers * transport_ms
            row = {"size": size, "set-up": setup, "cpu_ms_per_frame": round(per_frame, 1),
                   "of_which_transport_ms": round(receivers * transport_ms, 1)}
            for hz in (10, 30):
                row[f"cameras_at_{hz}hz"] = round(cores * 1000.0 / (per_frame * hz), 1)
            rows.append(row)
    return rows


def write(results: dict) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "multihost.json").write_text(json.dumps(results, indent=1))
    lines = ["## Several hosts: images over UDP between network namespaces (`bench/multihost.py`)", "",
             f"{results['machine']}; {results['when']}; {'quick' if results['quick'] else 'full'} run, "
             f"{results['seconds']} s per row. Camera host → compute host, sensor_msgs/Image bgr8, each host a network "
             "namespace with its own /dev/shm (all traffic over UDP through a bridge). Loss: "
             f"{results['loss_mechanism']} on the compute host's ingress, per packet (IP fragment). "
             "Latency = receive time − stamp at publish (one clock).", "",
             "### Transfer", "",
             "| size | Hz | loss % | QoS | UDP datagrams | published | received | lost | images/s | p50 ms | p95 ms | subscriber CPU ms/image |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["transfer"]:
        lines.append(f"| {r['size']} | {r['hz']} | {r['loss_pct']} | {r['qos']} | {r['datagrams']} | {r['published']} | "
                     f"{r['received']} | {r['lost']} | {r['images_per_s']} | {r['p50_ms']} | {r['p95_ms']} | "
                     f"{r['cpu_ms_per_image']} |")
    lines += ["", "Where `published` is below Hz × duration, the publishing process could not hold the rate on this "
              "machine (2.8 MB images, shared cores). `lost` counts frame numbers never received."]
    rec = [r["recovery_s"] for r in results["link_drop"] if r.get("recovery_s") is not None]
    lines += ["", f"### Link drop: camera host unplugged for {results['link_drop'][0]['link_drop_s'] if results['link_drop'] else '-'} s "
              "at 640x480 10 Hz, best effort", "",
              f"Recovery (link up → first image received) over {len(results['link_drop'])} runs: "
              + (f"mean {np.mean(rec):.2f} s, worst {max(rec):.2f} s, each {rec}" if rec else "no image after the link came back")
              + f"; runs without recovery: {len(results['link_drop']) - len(rec)}.", "",
              f"### Cameras per compute host ({results['cores']} cores, node defaults)", "",
              "Mean CPU per frame of each node's processor at its defaults (offline, the code the nodes run; "
              f"docking scene frames, {results['cost_frames']} per size) plus the measured subscriber CPU per "
              "received image (one copy per subscribing node process). Cameras = cores × 1000 / (ms per frame × Hz), "
              "with no headroom: an upper bound. The detector node keeps the newest frame, so past this it skips frames "
              "rather than falling behind.", "",
              "| size | set-up | CPU ms/frame | of which transport | cameras at 10 Hz | cameras at 30 Hz |",
              "|---|---|---|---|---|---|"]
    for r in results["cameras"]:
        lines.append(f"| {r['size']} | {r['set-up']} | {r['cpu_ms_per_frame']} | {r['of_which_transport_ms']} | "
                     f"{r['cameras_at_10hz']} | {r['cameras_at_30hz']} |")
    lines += ["", "Node CPU ms per frame, mean / median (a few of the docking tracker's frames cost far more "
              "than the median; capacity needs the mean):", "",
              "| size | " + " | ".join(results["node_costs"]["640x480"]) + " |", "|---|---|---|---|"]
    for size, costs in results["node_costs"].items():
        lines.append(f"| {size} | " + " | ".join(f"{c['mean']} / {c['median']}" for c in costs.values()) + " |")
    lines.append("")
    (RESULTS / "multihost.md").write_text("\n".join(lines) + "\n")


def plot(results: dict) -> None:
    from aircraft_docking_tracker.evaluation.plots import _pyplot, grouped_bars  # noqa: PLC0415

    plt = _pyplot()
    PLOTS.mkdir(parents=True, exist_ok=True)
    rows = [r for r in results["transfer"] if r["qos"] == "best effort" and r["datagrams"].startswith("1472")]
    losses = sorted({r["loss_pct"] for r in rows})
    groups = sorted({(r["size"], r["hz"]) for r in rows}, key=lambda g: (SIZES[g[0]][0], g[1]))
    series = {f"loss {loss} %": [next((100.0 * r["received"] / max(r["published"], 1) for r in rows
                                       if (r["size"], r["hz"]) == g and r["loss_pct"] == loss), 0.0) for g in groups]
              for loss in losses}
    fig, ax = plt.subplots(figsize=(8, 4))
    grouped_bars(ax, [f"{s} {hz} Hz" for s, hz in groups], series)
    ax.set_ylabel("images received [%]")
    ax.set_ylim(0, 125)
    ax.set_title("Camera host → compute host, best effort (sensor-data QoS)")
    ax.legend(ncol=len(series), loc="upper center")
    fig.tight_layout()
    fig.savefig(PLOTS / "multihost_received.png", dpi=100)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--costs-only", action="store_true",
                        help="keep the transfer rows of bench/results/multihost.json, measure the node costs again")
    parser.add_argument("--role", choices=("publish", "subscribe"), help=argparse.SUPPRESS)
    parser.add_argument("--size", default="640x480", help=argparse.SUPPRESS)
    parser.add_argument("--hz", type=float, default=10.0, help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, default=5.0, help=argparse.SUPPRESS)
    parser.add_argument("--reliable", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "publish":
        role_publish(args.size, args.hz, args.seconds, args.reliable, args.out)
        return 0
    if args.role == "subscribe":
        role_subscribe(args.reliable, args.seconds, args.out)
        return 0

    from aircraft_docking_tracker import netns  # noqa: PLC0415

    if args.costs_only:
        results = json.loads((RESULTS / "multihost.json").read_text())
        return finish(results, args.quick)
    reason = netns.unavailable_reason()
    if reason:
        print(f"bench/multihost.py: skipped: {reason}", file=sys.stderr)
        return 0
    seconds = 4.0 if args.quick else 8.0
    results = {"quick": args.quick, "seconds": seconds, "machine": f"{platform.machine()}, {os.cpu_count()} cores",
               "when": time.strftime("%Y-%m-%d"), "cores": os.cpu_count() or 1, "transfer": [], "link_drop": []}
    with tempfile.TemporaryDirectory(prefix="bench-multihost-") as tmp, netns.VirtualNetwork() as net:
        workdir = Path(tmp)
        camera, compute = net.add_host("camera"), net.add_host("compute")
        mechanisms = set()
        for cell in transfer_cells(args.quick):
            try:
                row = run_cell(net, camera, compute, cell, seconds, workdir)
            except netns.NetworkUnavailable as exc:
                print(f"skipped {cell}: {exc}", file=sys.stderr)
                continue
            mechanisms.add(row.get("loss_by") or "none")
            results["transfer"].append(row)
        results["loss_mechanism"] = ", ".join(sorted(mechanisms - {"none"})) or "not available"
        for _ in range(2 if args.quick else 3):
            results["link_drop"].append(run_cell(net, camera, compute, Cell("640x480", 10, link_drop_s=5.0),
                                                 seconds=14.0, workdir=workdir))
    return finish(results, args.quick)


def finish(results: dict, quick: bool) -> int:
    results["cost_frames"] = 15 if quick else 60
    results["node_costs"] = node_costs(results["cost_frames"])
    results["cameras"] = cameras_per_host(results["node_costs"], results["transfer"], results["cores"])
    write(results)
    plot(results)
    print((RESULTS / "multihost.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
