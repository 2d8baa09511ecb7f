"""Tools never destroy or silently truncate data (issue #16, item 4) and read split bags (item 7).

Each case was a real failure: ``run_offline in.mcap in.mcap`` truncated the input to 818 bytes;
``sot_track`` wrote nothing when a frame was corrupt; run_offline / sot_track / detect read a
truncated bag without a word; a run that stopped on an unknown type left a partial output; split
bags (``ros2 bag record --max-bag-size``) were refused.
"""
from __future__ import annotations

import os
import threading

import numpy as np
import pytest
import yaml
from std_msgs.msg import String

from aircraft_docking_tracker.docking import affine_group as ag
from aircraft_docking_tracker.io import mcap_record
from aircraft_docking_tracker import offline, sot_track
from aircraft_docking_tracker.io.bag import BagError, BagReader, BagWriter, check_outputs
from aircraft_docking_tracker.images import numpy_to_image
from aircraft_docking_tracker.io.mcap_play import Player, PlayOptions
from aircraft_docking_tracker.scenarios.messages import header, quad_to_polygon
from multi_target_tracker import detect

from ros_helpers import FakePlayerNode
from test_docking_filter import moving_target_scene

T0 = 1_000_000_000
STEP = 100_000_000


def write_scene_bag(path, frames=10, corrupt_at=None, **writer_kwargs):
    """``/image`` + ``/ground_truth/polygon``; frame ``corrupt_at`` has image data cut short."""
    scene = list(moving_target_scene(40, size=(160, 120)))[:frames]
    with BagWriter(path, **writer_kwargs) as writer:
        for k, (frame, X) in enumerate(scene):
            hdr = header(T0 + k * STEP)
            image = numpy_to_image(frame, "mono8", hdr)
            if k == corrupt_at:
                image.data = bytes(image.data)[:100]  # a camera driver bug: data shorter than step * height
            writer.write("/image", image, T0 + k * STEP)
            writer.write("/ground_truth/polygon", quad_to_polygon(ag.to_quad(X) / 2, hdr), T0 + k * STEP)
    return path


def killed_copy(src, dst, keep_fraction=0.6):
    """What a hard-killed recorder leaves: the first part of the file, no summary, no footer."""
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * keep_fraction)])
    return dst


def chatter_bag(path, n=20, **kwargs):
    with BagWriter(path, **kwargs) as writer:
        for i in range(n):
            writer.write("/chatter", String(data=f"m{i}"), T0 + i * STEP)
    return path


# ------------------------------------------------------------------ outputs that are inputs
def test_run_offline_refuses_to_write_over_its_input(tmp_path, capsys):
    bag = write_scene_bag(tmp_path / "in.mcap", frames=3)
    before = bag.read_bytes()
    (tmp_path / "link.mcap").symlink_to(bag)
    os.link(bag, tmp_path / "hard.mcap")
    for out in (bag, tmp_path / "link.mcap", tmp_path / "hard.mcap", tmp_path / "." / "in.mcap"):
        assert offline.main([str(bag), str(out), "--nodes", "docking_tracker", "--no-progress"]) == 2
        assert "would overwrite the input" in capsys.readouterr().err
    assert bag.read_bytes() == before
    # a bag directory as input, the same directory (or its file) as output
    folder = chatter_bag(tmp_path / "dirbag")
    files_before = {p.name: p.read_bytes() for p in folder.iterdir()}
    for out in (folder, folder / "dirbag_0.mcap"):
        assert offline.main([str(folder), str(out), "--nodes", "association", "--no-progress"]) == 2
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == files_before


def test_sot_track_detect_and_recover_refuse_to_overwrite_their_input(tmp_path):
    bag = write_scene_bag(tmp_path / "in.mcap", frames=3)
    before = bag.read_bytes()
    assert sot_track.main([str(bag), "--out", str(bag), "--no-progress"]) == 2
    assert sot_track.main([str(bag), "--quads", str(bag), "--no-progress"]) == 2
    assert detect.main([str(bag), "-o", str(bag), "--no-progress"]) == 2
    assert detect.main([str(bag), "--bag", str(bag), "--no-progress"]) == 2
    assert mcap_record.main(["--recover", str(bag), str(bag)]) == 2
    assert bag.read_bytes() == before
    with pytest.raises(BagError, match="would overwrite"):
        check_outputs([tmp_path], [bag])          # a bag directory output holding the input
    check_outputs(["-", None, tmp_path / "other.mcap"], [bag])  # stdout and other paths are fine


# ------------------------------------------------------------------ keep what was made
def test_sot_track_keeps_the_frames_before_a_corrupt_one(tmp_path, capsys):
    bag = write_scene_bag(tmp_path / "scene.mcap", frames=10, corrupt_at=6)
    out, quads = tmp_path / "boxes.txt", tmp_path / "quads.txt"
    assert sot_track.main([str(bag), "--out", str(out), "--quads", str(quads), "--no-progress"]) == 1
    assert len(np.loadtxt(out, delimiter=",")) == 6 and len(np.loadtxt(quads, delimiter=",")) == 6
    err = capsys.readouterr().err
    assert "frame 6" in err and "the 6 frames before it are written" in err


def test_a_failed_run_leaves_no_partial_output_and_keeps_the_old_one(tmp_path, capsys):
    # `image` of a type that is not installed: refused before anything is written
    src = tmp_path / "in.mcap"
    with BagWriter(src) as writer:
        writer.add_topic("/image", "vendor_msgs/msg/RawFrame", definition="uint8[] pixels\n")
        for i in range(5):
            writer.write_serialized("/image", "vendor_msgs/msg/RawFrame", bytes([0, 1, 0, 0, 0, 0, 0, 0]), T0 + i)
    out = tmp_path / "out.mcap"
    assert offline.main([str(src), str(out), "--nodes", "detector", "--no-progress"]) == 2
    assert "vendor_msgs/msg/RawFrame" in capsys.readouterr().err
    assert not out.exists() and not list(tmp_path.glob(".out.mcap.partial*"))
    # an atomic writer stopped by an exception leaves the previous output untouched
    chatter_bag(out, n=3)
    before = out.read_bytes()
    with pytest.raises(RuntimeError):
        with BagWriter(out, overwrite=True, atomic=True) as writer:
            writer.write("/chatter", String(data="new"), T0)
            raise RuntimeError("the run stops here")
    assert out.read_bytes() == before and not list(tmp_path.glob(".out.mcap.partial*"))


def test_topics_of_types_not_installed_here_are_copied_with_their_schema(tmp_path):
    src = tmp_path / "in.mcap"
    write_scene_bag(src, frames=2)
    mixed = tmp_path / "mixed.mcap"
    with BagWriter(mixed) as writer:
        reader = BagReader(src)
        for info in reader.topics.values():
            writer.add_topic_like(info)
        writer.add_topic("/vendor/status", "vendor_msgs/msg/Status", definition="int32 code\nstring text\n")
        for item in reader.messages():
            writer.write_serialized(item.topic, item.type_name, item.data, item.log_time_ns)
        writer.write_serialized("/vendor/status", "vendor_msgs/msg/Status", b"\x00\x01\x00\x00" + bytes(12), T0)
    out = tmp_path / "out.mcap"
    offline.run(mixed, out, ["docking_tracker"], progress=False)
    got = BagReader(out)
    assert got.topics["/vendor/status"].type_name == "vendor_msgs/msg/Status"
    assert got.topics["/vendor/status"].definition == "int32 code\nstring text\n"
    assert got.topics["/vendor/status"].count == 1 and got.topics["/docking/polygon"].count == 2


# ------------------------------------------------------------------ truncated bags are announced
def test_every_tool_warns_on_a_truncated_bag(tmp_path, capsys):
    full = write_scene_bag(tmp_path / "full.mcap", frames=12, chunk_size=20_000)
    cut = killed_copy(full, tmp_path / "killed.mcap")
    assert BagReader(cut).truncated and BagReader(cut).topics["/image"].count >= 3
    assert offline.main([str(cut), str(tmp_path / "o.mcap"), "--nodes", "docking_tracker", "--no-progress"]) == 0
    assert "truncated" in capsys.readouterr().err
    assert sot_track.main([str(cut), "--no-progress"]) == 0
    assert "truncated" in capsys.readouterr().err
    assert detect.main([str(cut), "-o", str(tmp_path / "b.txt"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "truncated" in err and "mcap_record --recover" in err


def test_a_damaged_chunk_is_skipped_and_reported(tmp_path):
    bag = chatter_bag(tmp_path / "c.mcap", n=60, chunk_size=300)
    reader = BagReader(bag)
    assert not reader.problem
    from mcap.reader import SeekingReader

    with open(bag, "rb") as stream:
        chunks = SeekingReader(stream).get_summary().chunk_indexes
    assert len(chunks) > 4
    data = bytearray(bag.read_bytes())
    middle = chunks[2].chunk_start_offset + chunks[2].chunk_length // 2
    data[middle:middle + 8] = bytes(8)           # a bad sector inside the third chunk
    bag.write_bytes(bytes(data))
    reader = BagReader(bag)
    got = [m.deserialize().data for m in reader.messages()]
    assert 40 < len(got) < 60 and got[0] == "m0" and got[-1] == "m59"
    assert "damaged chunk" in reader.problem


# ------------------------------------------------------------------ split bags
def test_split_bag_written_by_size_reads_as_one(tmp_path):
    folder = tmp_path / "split"
    with BagWriter(folder, max_bytes=4000, chunk_size=1000) as writer:
        for i in range(300):
            writer.write("/chatter", String(data=f"message {i:04d} " + "x" * 40), T0 + i * STEP)
    files = sorted(folder.glob("*.mcap"))
    assert len(files) >= 3
    meta = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["relative_file_paths"] == [f"split_{k}.mcap" for k in range(len(files))]
    assert sum(f["message_count"] for f in meta["files"]) == meta["message_count"] == 300
    assert all(f.stat().st_size < 2 * 4000 for f in files)  # the data section splits at 4000 B; plus summary
    reader = BagReader(folder)
    assert reader.message_count == 300 and reader.files == [folder / name for name in meta["relative_file_paths"]]
    assert [m.deserialize().data[:12] for m in reader.messages()] == [f"message {i:04d}" for i in range(300)]
    assert reader.duration_ns == 299 * STEP
    rosbags = pytest.importorskip("rosbags.rosbag2")
    with rosbags.Reader(folder) as theirs:
        assert theirs.message_count == 300 and len(list(theirs.messages())) == 300


def test_split_bag_by_duration_through_run_offline_and_the_player(tmp_path):
    folder = tmp_path / "scene"
    write_scene_bag(folder, frames=8, max_duration_ns=3 * STEP)
    assert len(list(folder.glob("*.mcap"))) == 3
    out = tmp_path / "out.mcap"
    offline.run(folder, out, ["docking_tracker"], progress=False)
    assert BagReader(out).topics["/image"].count == 8 and BagReader(out).topics["/docking/polygon"].count == 8

    node = FakePlayerNode()
    player = Player(node, BagReader(folder), PlayOptions(rate=100.0))
    thread = threading.Thread(target=player.run)
    thread.start()
    thread.join(timeout=30)
    assert player.report.published == 16 and len(node.publishers["/image"].sent) == 8


def test_split_needs_a_directory_output(tmp_path):
    with pytest.raises(BagError, match="bag directory"):
        BagWriter(tmp_path / "x.mcap", max_bytes=1000)


def test_mot_track_refuses_to_write_its_results_over_its_detections(tmp_path, capsys):
    from multi_target_tracker import mot_track

    det = tmp_path / "det.txt"
    det.write_text("1,-1,10,10,20,20,0.9,-1,-1,-1\n2,-1,11,10,20,20,0.9,-1,-1,-1\n")
    before = det.read_bytes()
    assert mot_track.main([str(det), "-o", str(det)]) == 2
    assert "would overwrite the input" in capsys.readouterr().err and det.read_bytes() == before
    assert mot_track.main([str(det), "-o", str(tmp_path / "results.txt")]) == 0


def test_an_atomic_directory_output_replaces_only_the_bags_own_files(tmp_path):
    src = write_scene_bag(tmp_path / "in.mcap", frames=3)
    out = tmp_path / "outbag"
    out.mkdir()
    (out / "notes.txt").write_text("the operator's notes")
    (out / "outbag_7.mcap").write_bytes(b"a stale split file of an older run")
    for _ in range(2):
        offline.run(src, out, ["docking_tracker"], progress=False)
    assert sorted(p.name for p in out.iterdir()) == ["metadata.yaml", "notes.txt", "outbag_0.mcap"]
    assert BagReader(out).topics["/docking/polygon"].count == 3
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.ros
def test_the_player_names_the_repair_of_a_truncated_recording(tmp_path):
    import subprocess
    import sys

    cut = killed_copy(chatter_bag(tmp_path / "full.mcap", n=200, chunk_size=500), tmp_path / "killed.mcap")
    result = subprocess.run([sys.executable, "-m", "aircraft_docking_tracker.io.mcap_play", str(cut), "--rate", "100"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "truncated" in result.stderr and "mcap_record --recover" in result.stderr


def test_evaluate_warns_on_a_damaged_chunk(tmp_path, capsys):
    from mcap.reader import SeekingReader

    from aircraft_docking_tracker.evaluation import evaluate
    from test_fuzz_bags import seed_bag

    bag = seed_bag(tmp_path / "rec.mcap", frames=12, chunk_size=1500)
    with open(bag, "rb") as stream:
        chunk = SeekingReader(stream).get_summary().chunk_indexes[3]
    data = bytearray(bag.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    bag.write_bytes(bytes(data))
    assert evaluate.main([str(bag), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "damaged" in err and "scored what could be read" in err


def test_train_cascade_refuses_to_save_its_model_over_a_training_bag(tmp_path, capsys):
    from multi_target_tracker import train_cascade

    bag = write_scene_bag(tmp_path / "train.mcap", frames=2)
    before = bag.read_bytes()
    assert train_cascade.main(["--bag", str(bag), "-o", str(bag)]) == 2
    assert "would overwrite the input" in capsys.readouterr().err  # refused before any data is read
    assert bag.read_bytes() == before


def test_an_empty_recording_is_a_bag_with_topics_and_no_messages(tmp_path):
    with BagWriter(tmp_path / "empty.mcap") as writer:
        writer.add_topic("/chatter", "std_msgs/msg/String")
    reader = BagReader(tmp_path / "empty.mcap")
    assert reader.topics["/chatter"].count == 0 and list(reader.messages()) == [] and reader.problem is None


def test_a_killed_recording_is_refused_by_rosbags_until_recovered(tmp_path):
    """What README and the player's warning say: indexed readers refuse it, --recover repairs it."""
    rosbags = pytest.importorskip("rosbags.rosbag2")

    cut = killed_copy(chatter_bag(tmp_path / "full.mcap", n=200, chunk_size=500), tmp_path / "killed.mcap")
    with pytest.raises(Exception, match="magic"):
        with rosbags.Reader(cut) as reader:
            list(reader.messages())
    assert "mcap_record --recover" in BagReader(cut).problem
    assert mcap_record.main(["--recover", str(cut), str(tmp_path / "fixed.mcap")]) == 0
    with rosbags.Reader(tmp_path / "fixed.mcap") as reader:
        assert reader.message_count == BagReader(cut).message_count > 50


def test_sot_track_keeps_the_frames_before_an_unreadable_image_file(tmp_path, capsys):
    import cv2

    folder = tmp_path / "frames"
    folder.mkdir()
    for k, (frame, _) in enumerate(list(moving_target_scene(40, size=(160, 120)))[:6]):
        cv2.imwrite(str(folder / f"{k:04d}.png"), frame)
    (folder / "0004.png").write_bytes(b"\x89PNG\r\n\x1a\n half a file")   # a copy that was cut short
    out = tmp_path / "boxes.txt"
    assert sot_track.main([str(folder), "--init", "30,40,40,30", "--out", str(out), "--no-progress"]) == 1
    assert len(np.loadtxt(out, delimiter=",")) == 4
    assert "frame 4" in capsys.readouterr().err


def test_a_split_bag_with_one_unreadable_file_keeps_the_others(tmp_path):
    folder = tmp_path / "split"
    write_scene_bag(folder, frames=9, max_duration_ns=3 * STEP)
    files = sorted(folder.glob("*.mcap"))
    assert len(files) == 3
    files[1].write_bytes(b"zeroed by a disk fault" + bytes(100))
    reader = BagReader(folder)
    assert reader.topics["/image"].count == 6 and len(list(reader.messages(["/image"]))) == 6
    assert "split_1.mcap" in reader.problem and "not an MCAP file" in reader.problem
    for f in (files[0], files[2]):
        f.write_bytes(b"")
    with pytest.raises(BagError, match="no file of the bag can be read"):
        BagReader(folder)
