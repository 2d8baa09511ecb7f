"""Fuzz: random and mutated bag bytes thrown at the bag reader, the player's reading path,
``run_offline`` and ``evaluate`` (issue #16). Seeded and time-bounded.

A mutation is one of: bits flipped anywhere, the file truncated at a random byte (a recorder killed
hard), a random span cut out (a chunk half gone), a span overwritten with zeros (a bad sector), a
chunk's bytes shuffled, or random bytes after the MCAP magic. What must hold for every input:

* the library (``BagReader``) opens it or raises ``BagError`` — never anything else;
* reading never raises once the bag is open (damage is reported by ``BagReader.problem``);
  deserialising raises ``BagError`` only;
* the tools (``run_offline``, ``evaluate``) return an exit code (0, or 2 with a message), never a
  traceback; the player publishes what it can read and returns;
* no hang (the whole run is a subprocess under a hard timeout) and bounded memory (its peak RSS).

The harness runs in a child process (``python test/test_fuzz_bags.py SEED BUDGET_S``) so that a
hang or a memory blow-up is measured from outside instead of taking the test runner down.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import random
import subprocess
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

import pytest
from memory_helpers import peak_rss_mb

HERE = Path(__file__).resolve().parent
SEEDS = (11, 12)
BUDGET_S = 12.0          # per seed, inside the child: well under a minute for the test in total
HARD_TIMEOUT_S = 120.0   # a child still running then has hung
MAX_RSS_MB = 700         # the child's peak: interpreter + rclpy + numpy + OpenCV is about 250 MB


# ----------------------------------------------------------------------------------- seed bags
def seed_bag(path: Path, frames: int = 12, chunk_size: int = 1500) -> Path:
    """A small recording of both cameras' kinds: images, detections, tracks, a docking polygon and
    the ground truth of each, in many small chunks (so that mutations hit chunk structure)."""
    import numpy as np

    from aircraft_docking_tracker.io.bag import BagWriter
    from aircraft_docking_tracker.object_table import DETECTION_DTYPE, TRACK_DTYPE
    from aircraft_docking_tracker.scenarios import messages as m

    rng = np.random.default_rng(0)
    with BagWriter(path, chunk_size=chunk_size) as bag:
        for k in range(frames):
            t = 1_000_000_000 + k * 100_000_000
            hdr = m.header(t)
            bag.write("/image", m.image_msg(rng.integers(0, 255, (12, 16, 3), dtype=np.uint8), hdr), t)
            truth = np.zeros(2, TRACK_DTYPE)
            truth["id"], truth["x"], truth["y"], truth["w"], truth["h"] = [1, 2], [2 + k, 9], [3, 4 + k], 5, 6
            truth["state"] = 1
            bag.write("/ground_truth", m.cloud_msg(truth, hdr), t)
            dets = np.zeros(2, DETECTION_DTYPE)
            dets["x"], dets["y"], dets["w"], dets["h"], dets["score"] = truth["x"] + 1, truth["y"], 5, 6, 1.0
            bag.write("/detections", m.cloud_msg(dets, hdr), t + 1)
            bag.write("/tracks", m.cloud_msg(truth, hdr), t + 2)
            quad = np.array([[2, 3], [9, 3], [9, 8], [2, 8]], float) + k
            bag.write("/ground_truth/polygon", m.quad_to_polygon(quad, hdr), t)
            bag.write("/docking/polygon", m.quad_to_polygon(quad + 0.5, hdr), t + 3)
    return path


def mutate(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    b = bytearray(data)
    kind = rng.choice(["flip", "flip", "truncate", "cut", "zeros", "shuffle", "random"])
    if kind == "flip":
        for _ in range(rng.randint(1, 16)):
            k = rng.randrange(len(b))
            b[k] ^= 1 << rng.randrange(8)
    elif kind == "truncate":
        b = b[: rng.randrange(len(b))]
    elif kind == "cut":
        start = rng.randrange(len(b))
        b = b[:start] + b[start + rng.randint(1, 4000):]
    elif kind == "zeros":
        start = rng.randrange(len(b))
        n = rng.randint(1, 512)
        b[start:start + n] = bytes(min(n, len(b) - start))
    elif kind == "shuffle":
        start = rng.randrange(len(b))
        span = b[start:start + rng.randint(2, 256)]
        rng.shuffle(span)
        b[start:start + len(span)] = span
    else:
        b = bytearray(b"\x89MCAP0\r\n" + rng.randbytes(rng.randint(0, 3000)))
    return kind, bytes(b)


def split_bag(folder: Path, damaged: bytes, sound: bytes, rng: random.Random) -> Path:
    """A rosbag2 directory of two files whose metadata.yaml may be damaged too."""
    import shutil

    import yaml

    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    names = [f"{folder.name}_0.mcap", f"{folder.name}_1.mcap"]
    (folder / names[0]).write_bytes(damaged)
    (folder / names[1]).write_bytes(sound)
    text = yaml.safe_dump({"rosbag2_bagfile_information": {"version": 9, "storage_identifier": "mcap",
                                                           "relative_file_paths": names}})
    if rng.random() < 0.5:
        raw = bytearray(text.encode())
        for _ in range(rng.randint(1, 6)):
            raw[rng.randrange(len(raw))] = rng.randrange(256)
        (folder / "metadata.yaml").write_bytes(bytes(raw))
    else:
        (folder / "metadata.yaml").write_text(text)
    return folder


# ----------------------------------------------------------------------------------- targets
def _read(path: Path) -> str:
    from aircraft_docking_tracker.io.bag import BagError, BagReader

    try:
        reader = BagReader(path)
    except BagError:
        return "refused"
    n = 0
    for item in reader.messages():
        n += 1
        try:
            item.deserialize()
        except BagError:
            pass
    list(reader.messages(topics=["/tracks"], start_ns=reader.start_ns + 300_000_000))
    assert n <= reader.message_count or reader.truncated or reader.problem is not None, "more messages than counted"
    return "damaged" if reader.problem else "ok"


def _play(path: Path) -> str:
    from aircraft_docking_tracker.io.bag import BagError, BagReader
    from aircraft_docking_tracker.io.mcap_play import Player, PlayOptions
    from ros_helpers import FakePlayerNode

    try:
        reader = BagReader(path)
    except BagError:
        return "refused"
    report = Player(FakePlayerNode(), reader, PlayOptions(rate=1e6)).run()
    return "damaged" if reader.problem else ("ok" if report.published == reader.message_count else "partial")


def _tool(main, argv) -> str:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(argv)
    assert rc in (0, 2), f"exit code {rc}"
    assert "Traceback" not in err.getvalue()
    return "ok" if rc == 0 else "refused"


def _offline(path: Path, work: Path) -> str:
    from aircraft_docking_tracker import offline

    out = work / "out.mcap"
    result = _tool(offline.main, [str(path), str(out), "--nodes", "association", "--no-progress"])
    assert out.exists() == (result == "ok"), "an output after a refusal, or none after success"
    out.unlink(missing_ok=True)
    return result


def _evaluate(path: Path) -> str:
    from aircraft_docking_tracker.evaluation import evaluate

    return _tool(evaluate.main, [str(path), "--quiet"])


def run_fuzz(seed: int, budget_s: float, work: Path) -> dict:
    """Mutated and random bags through each target until the time budget is spent."""
    rng = random.Random(seed)
    work.mkdir(parents=True, exist_ok=True)
    pristine = seed_bag(work / "seed.mcap").read_bytes()
    outcomes: Counter = Counter()
    crashes: list[str] = []
    pristine_failures: list[str] = []
    slowest = 0.0
    # targets in a fixed cycle (each gets its share however few cases the budget allows)
    cycle = ["read", "play", "read", "offline", "read", "read", "evaluate", "read", "play", "read"]
    started = time.monotonic()
    n = 0
    while time.monotonic() - started < budget_s:
        kind, data = mutate(pristine, rng)
        target = cycle[n % len(cycle)]
        if n % 23 == 0:  # the sound bag now and then: every target must read it whole
            kind, data = "pristine", pristine
        if kind != "pristine" and rng.random() < 0.15:  # a split bag: one damaged file, one sound, a damaged metadata.yaml
            path = split_bag(work / f"split_{n % 2}", data, pristine, rng)
            kind = "split/" + kind
        else:
            path = work / f"fuzz_{n % 2}.mcap"
            path.write_bytes(data)
        t0 = time.monotonic()
        try:
            if target == "read":
                result = _read(path)
            elif target == "play":
                result = _play(path)
            elif target == "offline":
                result = _offline(path, work)
            else:
                result = _evaluate(path)
            outcomes[f"{target}:{result}"] += 1
            if kind == "pristine" and result != "ok":
                pristine_failures.append(f"{target}: {result}")
        except Exception as exc:  # noqa: BLE001 - every escape is a finding
            crashes.append(f"{target} on {kind} (case {n}): {type(exc).__name__}: {exc}\n"
                           + "".join(traceback.format_exc(limit=6)))
            outcomes[f"{target}:CRASH"] += 1
        slowest = max(slowest, time.monotonic() - t0)
        n += 1
    return {"seed": seed, "cases": n, "outcomes": dict(outcomes), "crashes": crashes[:5],
            "pristine_failures": pristine_failures,
            "crash_count": len(crashes), "slowest_case_s": round(slowest, 3),
            "peak_rss_mb": peak_rss_mb()}


# ----------------------------------------------------------------------------------- the test
@pytest.mark.parametrize("seed", SEEDS)
def test_mutated_and_random_bags_never_crash_hang_or_blow_up(seed, tmp_path):
    result = subprocess.run([sys.executable, __file__, str(seed), str(BUDGET_S), str(tmp_path)],
                            capture_output=True, text=True, timeout=HARD_TIMEOUT_S, env=os.environ.copy())
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["crash_count"] == 0, "\n\n".join(report["crashes"])
    assert report["pristine_failures"] == [], report
    # the harness really ran (a floor, not a speed claim: ~1000 cases per seed on an idle machine),
    # every target was exercised, and damaged input was refused somewhere
    assert report["cases"] >= 50, report
    for target in ("read", "play", "offline", "evaluate"):
        assert sum(v for k, v in report["outcomes"].items() if k.startswith(target + ":")) >= 5, report
    assert sum(v for k, v in report["outcomes"].items() if k.endswith(":refused")) > 0, report
    assert report["peak_rss_mb"] < MAX_RSS_MB, report


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    print(json.dumps(run_fuzz(int(sys.argv[1]), float(sys.argv[2]), Path(sys.argv[3]))))
