"""``sot_track``: the docking tracker's core over a frame folder, a video or a bag (no DDS).

    sot_track ../shared/data/sot/Car4 --out car4.txt                 # OTB folder, GT's first box
    sot_track frames/ --init 70,51,107,87 --method pf --out r.txt     # any image folder
    sot_track video.avi --init 10,20,50,40 --quads quads.txt
    sot_track docking3.mcap --out r.txt          # bag: `image` + first `ground_truth/polygon`
    sot_track docking3.mcap --guidance.stand-file stand3.yaml --guidance g.csv   # and the docking guidance

Writes one ``x,y,w,h`` per frame (the axis-aligned box of the tracked quadrilateral, 0-based
pixels, OTB layout; NaN while lost is *not* used: the filter's box is always written) and, with
``--quads``, one ``x1,y1,...,x4,y4`` line per frame (TL, TR, BR, BL). With ground truth (an OTB or
TinyTLP ``groundtruth_rect.txt`` beside the frames, or the bag's ``ground_truth/polygon``) it
prints the OTB success AUC and precision at 20 px. Parameters: ``config/docking_tracker.yaml``
(``--params-file``) overridden by ``--name value`` options, the very same dataclass as the node.

With a stand file (``--guidance.stand-file``) each frame is also guided as the node guides it
(:meth:`~aircraft_docking_tracker.docking.guidance.DockingGuidance.guide_frame`: the nose wheel measured
in the frame, at the bag's image stamps or ``--fps``);
``--guidance`` writes ``frame,distance_m,lateral_m,speed_mps,state`` per frame, and a bag's
``ground_truth/guidance`` is scored (``evaluation.guidance_metrics``).
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator

import cv2
import numpy as np
from tqdm import tqdm

from .config import ConfigError, add_config_arguments, config_from_arguments, tool_parameters
from .io.bag import check_outputs
from .docking.guidance import PARAM_PREFIX as GUIDANCE_PREFIX, GuidanceConfig, survey_note
from .docking.tracker import LOST, TRACKING, DockingConfig, DockingTracker
from .geometry import quad_to_box

NODE_NAME = "docking_tracker"
VIDEO_SUFFIXES = (".avi", ".mp4", ".mkv", ".mov", ".webm", ".mpg", ".mpeg")


class SequenceError(ValueError):
    """An input that is not a frame folder, a video or a bag with images."""


@dataclass
class Sequence:
    """Grey frames (lazily read) and the ground truth if known (NaN = absent): (N, 4) boxes from
    OTB / TinyTLP files (scored box against box, as OTB does) or (N, 4, 2) quadrilaterals from a
    bag (scored by polygon IoU)."""

    frames: Iterable[np.ndarray]
    count: int | None
    gt: np.ndarray | None = None
    name: str = ""
    files: list[Path] = field(default_factory=list)  # what is read: no output may overwrite these
    problem: Callable[[], str | None] = lambda: None  # a truncated or damaged bag, in words
    stamps: list | None = None                        # a bag's image stamps [ns] (None: frames at --fps)
    guidance: np.ndarray | None = None                # a bag's ground_truth/guidance rows, by image (NaN: absent)


@dataclass
class TrackRun:
    """What one run over a sequence produced, per frame."""

    quads: np.ndarray
    states: np.ndarray
    scores: np.ndarray
    particles: np.ndarray
    step_seconds: np.ndarray
    extra: dict = field(default_factory=dict)
    stopped: str | None = None  # why the run ended before the sequence did (a frame that does not read)
    guidance: np.ndarray | None = None  # with a DockingGuidance: one GUIDANCE_DTYPE row per frame
    guidance_seconds: np.ndarray | None = None  # and the time each frame's guidance took (after the tracker's step)

    @property
    def boxes(self) -> np.ndarray:
        return quad_to_box(self.quads)


# --------------------------------------------------------------------------- inputs
def open_sequence(path: str | Path) -> Sequence:
    """A frame folder (OTB / TinyTLP with ``groundtruth_rect.txt`` or bare images), a video or a bag."""
    path = Path(path)
    if path.suffix == ".mcap" or (path.is_dir() and any(path.glob("*.mcap"))):
        return _bag_sequence(path)
    if path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES:
        return _video_sequence(path)
    if path.is_dir():
        from .scenarios.datasets import list_frames, read_sot_boxes  # noqa: PLC0415

        files = list_frames(path)
        gt = None
        if (path / "groundtruth_rect.txt").is_file():
            gt = read_sot_boxes(path / "groundtruth_rect.txt")[0]
        frames = (_read_frame(f) for f in files)
        return Sequence(frames, len(files), gt, path.name,
                        files=[path, *files, path / "groundtruth_rect.txt"])
    raise SequenceError(f"{path}: not a frame folder, a video ({', '.join(VIDEO_SUFFIXES)}) or an .mcap bag")


def _read_frame(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise SequenceError(f"{path}: cannot be read as an image")
    return image


def _video_sequence(path: Path) -> Sequence:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise SequenceError(f"{path}: cannot be opened as a video")
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) or None

    def frames() -> Iterator[np.ndarray]:
        try:
            while True:
                ok, bgr = capture.read()
                if not ok:
                    return
                yield bgr
        finally:
            capture.release()
    return Sequence(frames(), count, None, path.stem, files=[path])


def _bag_sequence(path: Path, image_topic: str = "image", gt_topic: str = "ground_truth/polygon") -> Sequence:
    from .io.bag import BagError, BagReader, header_stamp_ns, stamp_to_ns  # noqa: PLC0415
    from .images import to_mono8_or_bgr8  # noqa: PLC0415
    from .docking.guidance import GUIDANCE_DTYPE  # noqa: PLC0415
    from .object_table import cloud_to_table  # noqa: PLC0415
    from .scenarios.messages import GT_GUIDANCE, polygon_to_quad  # noqa: PLC0415

    reader = BagReader(path)
    topics = {name.lstrip("/"): name for name in reader.topics}
    if image_topic not in topics:
        raise SequenceError(f"{path}: no '{image_topic}' topic (has {sorted(topics)})")
    def decoded(topic: str) -> Iterator:
        """Messages of ``topic``, None for one that does not deserialise (the run stops there)."""
        for item in reader.messages([topic]):
            try:
                yield item.deserialize()
            except BagError:
                yield None

    gt_by_stamp, guidance_by_stamp = {}, {}
    if gt_topic in topics:
        for msg in decoded(topics[gt_topic]):
            if msg is not None:
                gt_by_stamp[stamp_to_ns(msg.header.stamp)] = polygon_to_quad(msg)
    if GT_GUIDANCE in topics:
        for msg in decoded(topics[GT_GUIDANCE]):
            if msg is not None:
                guidance_by_stamp[stamp_to_ns(msg.header.stamp)] = cloud_to_table(msg, GUIDANCE_DTYPE)[0]
    stamps = []                      # the images' header stamps, read without decoding the pixels
    for item in reader.messages([topics[image_topic]]):
        try:
            stamps.append(header_stamp_ns(item.data))
        except BagError:
            stamps.append(None)
    gt = np.stack([gt_by_stamp.get(s, np.full((4, 2), np.nan)) for s in stamps]) if gt_by_stamp else None
    absent = np.array([(np.nan, np.nan, np.nan, -1)], dtype=GUIDANCE_DTYPE)[0]
    guidance = np.array([guidance_by_stamp.get(s, absent) for s in stamps], dtype=GUIDANCE_DTYPE) \
        if guidance_by_stamp else None
    count = reader.topics[topics[image_topic]].count

    def frames() -> Iterator[np.ndarray]:
        for _, msg, _ in reader.ros_messages([topics[image_topic]]):
            yield to_mono8_or_bgr8(msg)
    return Sequence(frames(), count, gt, path.stem, files=[*reader.files, reader.bag_path],
                    problem=lambda: reader.problem, stamps=stamps, guidance=guidance)


# --------------------------------------------------------------------------- the run
def track(frames: Iterable[np.ndarray], init, config: DockingConfig, count: int | None = None,
          progress: bool = True, desc: str = "sot_track", detections: Iterable | None = None,
          guidance=None, stamps: Iterable[int] | None = None) -> TrackRun:
    """Run the docking tracker over ``frames`` (grey, or BGR: tracked in grey) from ``init`` (box, quadrilateral or
    state; None: wait for a detection).

    The first frame starts the filter; each later frame is one ``DockingTracker.step`` (timed
    alone: reading and decoding the frames are not in ``step_seconds``), given the frame's detection
    table from ``detections`` if any (re-acquisition and the override rule, as the node does). A
    frame that cannot be read or decoded (a ``ValueError`` from ``frames``) ends the run: what came
    before it is kept and ``TrackRun.stopped`` says which frame and why. Frames without a track
    (waiting) have NaN quadrilaterals. With ``guidance`` (a ``DockingGuidance``) each frame is also guided, at
    its stamp from ``stamps`` [ns].
    """
    tracker = DockingTracker(config)
    tables = iter(detections) if detections is not None else None
    quads, states, scores, particles, seconds, guided, guide_seconds = [], [], [], [], [], [], []
    stamp_iter = iter(stamps) if stamps is not None else None
    stopped = None
    iterator = iter(frames)
    bar = tqdm(total=count, desc=desc, disable=not progress, unit="frame")
    index = 0
    while True:
        try:
            frame = next(iterator)
        except StopIteration:
            break
        except ValueError as exc:
            stopped = f"frame {index} cannot be read: {exc}"
            break
        bar.update(1)
        table = next(tables, None) if tables is not None else None
        t0 = time.perf_counter()
        result = tracker.start(frame, init) if index == 0 and init is not None else tracker.step(frame, table)
        seconds.append(time.perf_counter() - t0)
        quads.append(result.quad if result.quad is not None else np.full((4, 2), np.nan))
        states.append(result.state)
        scores.append(result.score)
        particles.append(result.particles)
        if guidance is not None:
            stamp = int(next(stamp_iter))
            t0 = time.perf_counter()
            guided.append(guidance.guide_frame(frame, result.quad, result.state == TRACKING, result.state == LOST,
                                               stamp).row()[0])
            guide_seconds.append(time.perf_counter() - t0)
        index += 1
    bar.close()
    if not quads:
        raise SequenceError(stopped or "the sequence has no frames")
    return TrackRun(np.array(quads), np.array(states), np.array(scores), np.array(particles), np.array(seconds),
                    stopped=stopped, guidance=np.array(guided) if guidance is not None else None,
                    guidance_seconds=np.array(guide_seconds) if guidance is not None else None)


def score_run(run: TrackRun, gt: np.ndarray) -> dict:
    """OTB scores of a run: boxes against (N, 4) box ground truth, quadrilaterals against (N, 4, 2)."""
    from .evaluation.sot_metrics import score_sequence  # noqa: PLC0415

    gt = np.asarray(gt, dtype=float)
    return score_sequence(run.boxes if gt.ndim == 2 else run.quads, gt)


def write_results(run: TrackRun, out: Path | None, quads_out: Path | None) -> None:
    if out is not None:
        np.savetxt(out, run.boxes, fmt="%.2f", delimiter=",")
    if quads_out is not None:
        np.savetxt(quads_out, run.quads.reshape(len(run.quads), 8), fmt="%.2f", delimiter=",")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sot_track", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", type=Path, help="frame folder, video file or .mcap bag")
    parser.add_argument("--init", help="initial box x,y,w,h (0-based pixels); default: the ground truth's first")
    parser.add_argument("--out", type=Path, help="write x,y,w,h per frame here (default: print a summary only)")
    parser.add_argument("--quads", type=Path, help="write the quadrilaterals x1,y1,...,x4,y4 per frame here")
    parser.add_argument("--max-frames", type=int, default=0, help="stop after this many frames (0: all)")
    parser.add_argument("--params-file", type=Path, default=None,
                        help="ROS 2 parameter file (default: config/docking_tracker.yaml)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--guidance", type=Path, help="with --guidance.stand-file: write frame,distance_m,lateral_m,"
                        "speed_mps,state per frame here")
    parser.add_argument("--fps", type=float, default=14.0,
                        help="frame rate of a folder or video for the guidance's speed (a bag has its stamps)")
    add_config_arguments(parser, DockingConfig)
    add_config_arguments(parser, GuidanceConfig, GUIDANCE_PREFIX)
    return parser


def guidance_config(args, base: dict) -> GuidanceConfig:
    """The guidance's parameters: the parameter file's ``guidance.*`` overridden by ``--guidance.*`` options."""
    own = {k[len(GUIDANCE_PREFIX):]: v for k, v in base.items() if k.startswith(GUIDANCE_PREFIX)}
    return config_from_arguments(GuidanceConfig, args, GUIDANCE_PREFIX, base=own)


def guidance_for(config: GuidanceConfig, stamps: list | None, fps: float):
    """(a ``DockingGuidance`` for the stand file, the frames' stamps [ns]: the bag's, or ``fps`` apart), or
    (None, None) without a stand file."""
    if not config.stand_file:
        return None, None
    from .docking.guidance import DockingGuidance  # noqa: PLC0415
    from .docking.stand import load_stand  # noqa: PLC0415

    if stamps is None or any(s is None for s in stamps):
        stamps = (round(i * 1e9 / fps) for i in itertools.count())
    return DockingGuidance(load_stand(config.stand_file), config), stamps


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        base = tool_parameters(args.params_file, "docking_tracker.yaml", NODE_NAME)
        config = config_from_arguments(DockingConfig, args, base=base)
        guided = guidance_config(args, base)      # validated: a stand file that does not load fails before the run
        if args.guidance and not guided.stand_file:
            raise ConfigError("--guidance needs a stand file (--guidance.stand-file)")
        seq = open_sequence(args.input)
        check_outputs([args.out, args.quads, args.guidance], seq.files, "sot_track")
        if seq.problem():
            print(f"sot_track: warning: {seq.problem()}", file=sys.stderr)
        if args.init:
            init = np.array([float(v) for v in args.init.split(",")])
            if init.shape != (4,):
                raise SequenceError(f"--init needs x,y,w,h, got {args.init!r}")
        elif seq.gt is not None and np.isfinite(seq.gt[0]).all():
            init = seq.gt[0]
        else:
            raise SequenceError("no --init box and no ground truth to take the first box from")
        frames, count = seq.frames, seq.count
        if args.max_frames > 0:
            frames = (f for i, f in zip(range(args.max_frames), frames))
            count = min(count or args.max_frames, args.max_frames)
        guidance, stamps = guidance_for(guided, seq.stamps, args.fps)
        if guidance is not None:
            print(f"sot_track: {survey_note(guidance)[1]}", file=sys.stderr)
        run = track(frames, init, config, count, progress=not args.no_progress, guidance=guidance, stamps=stamps)
    except (ConfigError, ValueError, OSError) as exc:
        print(f"sot_track: {exc}", file=sys.stderr)
        return 2
    write_results(run, args.out, args.quads)
    n = len(run.quads)
    guidance_line = ""
    if run.guidance is not None:
        rows = run.guidance
        guided_ms, tracked_ms = run.guidance_seconds * 1e3, run.step_seconds * 1e3
        guidance_line = (f"; guidance {np.mean(guided_ms):.2f} ms/frame (p95 {np.percentile(guided_ms, 95):.2f}) "
                         f"beside the tracker's {np.mean(tracked_ms[1:] if n > 1 else tracked_ms):.1f}")
        if args.guidance:
            np.savetxt(args.guidance, np.c_[np.arange(n), rows["distance_m"], rows["lateral_m"], rows["speed_mps"],
                                            rows["state"]], fmt=["%d", "%.3f", "%.3f", "%.3f", "%d"], delimiter=",",
                       header="frame,distance_m,lateral_m,speed_mps,state", comments="")
        if seq.guidance is not None:
            from .evaluation.guidance_metrics import guidance_errors  # noqa: PLC0415

            e = guidance_errors(rows, seq.guidance[:n])
            guidance_line += (f"; within the last 15 m: lateral p95 {e['lateral_near_p95']:.2f} m, "
                             f"distance p95 {e['distance_near_p95']:.2f} m; STOP first shown "
                             + (f"{e['stop_at_m']:.2f} m before the mark" if not e["stop_missed"] else "never"))
    if run.stopped:
        print(f"sot_track: error: stopped early, {run.stopped}; the {n} frames before it are "
              f"{'written' if args.out or args.quads else 'scored'}", file=sys.stderr)
    fps = (n - 1) / max(run.step_seconds[1:].sum(), 1e-9) if n > 1 else float("nan")
    line = (f"{seq.name}: {n} frames, {config.method}, {fps:.1f} frames/s (tracker only), "
            f"particles/frame mean {run.particles[1:].mean() if n > 1 else 0:.0f}, "
            f"lost frames {int((run.states == 1).sum())}")
    if seq.gt is not None:
        scores = score_run(run, seq.gt[:n])
        line += f", success AUC {scores['success_auc']:.3f}, precision@20 {scores['precision']:.3f}"
    print(line + guidance_line)
    return 1 if run.stopped else 0


if __name__ == "__main__":
    sys.exit(main())
