"""Train the UAV set-up's patch network (multi_target_tracker/patch_net.py).

    python tools/train_uav_patch_net.py [--out multi_target_tracker/models/uav_vehicles_patch_net.json]

Needs PyTorch (this tool only: ``pip install torch``; the package runs the stored ONNX graph with OpenCV).

1. **Samples** (``UAV_TRAIN_SEEDS`` only): the set-up's candidate groups (config/uav_camera.yaml without a patch
   network: every group of at least ``min_neighbors`` windows, its box the box regressor's member-statistics box,
   ``Detector.candidates``) on every 4th frame of the first ``--train-scenes`` training scenes of difficulty 1 and
   half as many of difficulty 2. A group is a vehicle when its box overlaps a counted vehicle (at least 30 %
   visible, border-cut ones included: what the demo's MOT scoring counts) by IoU >= 0.3, and its box target is that
   vehicle's box; background when it overlaps no counted vehicle by 0.1, whatever else it lies on: ground, canopy,
   smoke, or a vehicle hidden under them (less than 30 % visible, which the MOT scoring counts a track on as a false
   positive). The groups in between are left out of both losses.
2. **Network**: four 3x3 convolutions (16, 32, 64, 64 channels, ReLU, 2x2 max pooling after each of the first
   three), a 128-unit layer and :data:`patch_net.OUTPUTS`. Loss: binary cross-entropy of the log odds (the classes
   weighted equally) plus 4 x the smooth L1 (beta 0.05) of the vehicle samples' box edges. Adam (weight decay
   1e-4), one-cycle learning rate (peak 3e-3), batches of 128, ``--epochs``; each batch turned by one of the
   square's 8 symmetries at random (a nadir view has no up) and its brightness and colour balance jittered.
3. Writes the ONNX graph (opset 11) beside its JSON header (``size``, ``grow``, the samples and the training).

The operating point (``verifier_threshold`` on the verifier's and the network's summed log odds) is chosen on the
tuning seeds by ``bench/uav_tracking.py``; the evaluation seeds are not touched here.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tools"))

from aircraft_docking_tracker.geometry import box_iou  # noqa: E402
from multi_target_tracker.detector import MODELS_DIR  # noqa: E402
from multi_target_tracker.patch_net import OUTPUTS, PatchNet, encode_boxes, header, patches, square_regions  # noqa: E402
from train_uav_verifier import parse_overrides, scene_frames, setup_detector, training_scenes  # noqa: E402

SIZE = 48          # patch side [px]
GROW = 1.6         # region side / the box's longer side
POSITIVE_IOU, NEGATIVE_IOU, COUNTED_VISIBLE = 0.3, 0.1, 0.3   # IoU with a counted vehicle; what is counted


def samples(det, scenes, every: int = 4):
    """``(patches, best IoU with a counted vehicle, box targets)`` of the candidate groups of ``scenes``: the
    counted vehicle's box of best IoU as the target (:func:`labels` reads the IoU)."""
    cfg = det.config
    crops, on_counted, targets = [], [], []
    for seed, difficulty in scenes:
        for bgr, truth, hidden in scene_frames(seed, difficulty, every, COUNTED_VISIBLE):
            boxes, _ = det.candidates(bgr, det.raw(bgr), cfg.window_margin)
            if not len(boxes):
                continue
            counted = truth[~hidden]
            iou = box_iou(boxes[:, None], counted[None]) if len(counted) else np.zeros((len(boxes), 0))
            best = iou.argmax(axis=1) if len(counted) else np.zeros(len(boxes), np.int64)
            on_counted.append(iou.max(axis=1) if len(counted) else np.zeros(len(boxes)))
            crops.append(patches(bgr, boxes, SIZE, GROW))
            goal = counted[best] if len(counted) else np.zeros((len(boxes), 4))
            targets.append(encode_boxes(goal, square_regions(boxes, GROW)))
        print(f"training seed {seed}: {sum(len(v) for v in on_counted)} groups so far", flush=True)
    return np.concatenate(crops), np.concatenate(on_counted), np.concatenate(targets)


def labels(on_counted: np.ndarray) -> np.ndarray:
    """1 vehicle, 0 background, -1 left out, from each group's best IoU with a counted vehicle (module docstring)."""
    return np.where(on_counted >= POSITIVE_IOU, 1, np.where(on_counted < NEGATIVE_IOU, 0, -1))


def train(crops: np.ndarray, label: np.ndarray, targets: np.ndarray, epochs: int, seed: int):
    """The trained network (a ``torch.nn.Module`` in eval mode) and the last epoch's mean loss."""
    import torch  # noqa: PLC0415 (the tool's own dependency)
    from torch import nn  # noqa: PLC0415
    import torch.nn.functional as F  # noqa: PLC0415,N812

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)

    class Net(nn.Module):
        def __init__(self):
            super().__init__()
            self.convs = nn.ModuleList([nn.Conv2d(a, b, 3, padding=1) for a, b in ((3, 16), (16, 32), (32, 64),
                                                                                   (64, 64))])
            self.hidden = nn.Linear(64 * (SIZE // 8) ** 2, 128)
            self.out = nn.Linear(128, len(OUTPUTS))

        def forward(self, x):
            for k, conv in enumerate(self.convs):
                x = F.relu(conv(x))
                if k < 3:
                    x = F.max_pool2d(x, 2)
            return self.out(F.relu(self.hidden(x.flatten(1))))

    x_all = torch.from_numpy(crops).permute(0, 3, 1, 2).float().div(255.0).sub(0.5)
    y_all = torch.from_numpy(label).float()
    t_all = torch.from_numpy(targets).float()
    net = Net()
    optimiser = torch.optim.Adam(net.parameters(), 1e-3, weight_decay=1e-4)
    batches = (len(x_all) + 127) // 128
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, 3e-3, total_steps=epochs * batches)
    pos_weight = torch.tensor(float((y_all == 0).sum()) / max(float((y_all == 1).sum()), 1.0))
    mean_loss = float("nan")
    for epoch in range(epochs):
        net.train()
        order, total, start = torch.from_numpy(rng.permutation(len(x_all))), 0.0, time.time()
        for first in range(0, len(x_all), 128):
            batch = order[first:first + 128]
            x, y, t = x_all[batch], y_all[batch], t_all[batch]
            if rng.random() < 0.5:      # mirror left-right: x -> -x
                x, t = x.flip(3), torch.stack([-t[:, 2], t[:, 1], -t[:, 0], t[:, 3]], 1)
            if rng.random() < 0.5:      # mirror top-bottom
                x, t = x.flip(2), torch.stack([t[:, 0], -t[:, 3], t[:, 2], -t[:, 1]], 1)
            if rng.random() < 0.5:      # transpose: x <-> y
                x, t = x.transpose(2, 3), t[:, [1, 0, 3, 2]]
            gain = 1 + 0.2 * (torch.from_numpy(rng.random((len(batch), 1, 1, 1))).float() - 0.5)
            shift = 0.1 * (torch.from_numpy(rng.random((len(batch), 3, 1, 1))).float() - 0.5)
            out = net(x * gain + shift)
            judged, vehicle = y >= 0, y == 1
            loss = torch.zeros(())
            if judged.any():
                loss = loss + F.binary_cross_entropy_with_logits(out[judged, 0], y[judged], pos_weight=pos_weight)
            if vehicle.any():
                loss = loss + 4.0 * F.smooth_l1_loss(out[vehicle, 1:], t[vehicle], beta=0.05)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += loss.item() * len(batch)
        mean_loss = total / len(x_all)
        print(f"epoch {epoch + 1}/{epochs}: loss {mean_loss:.4f} ({time.time() - start:.0f} s)", flush=True)
    return net.eval(), mean_loss


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(MODELS_DIR / "uav_vehicles_patch_net.json"),
                        help="the JSON header; the ONNX graph is written beside it (same name, .onnx)")
    parser.add_argument("--train-scenes", type=int, default=100, help="training scenes of difficulty 1 (half as many "
                        "of difficulty 2; at most 100, where difficulty 2's seeds begin); the shipped network: 100, "
                        "session 43's 60 (tuning MOTA 0.755 against 0.711, docs/uav_camera.md)")
    parser.add_argument("--epochs", type=int, default=12)
    parser.add_argument("--seed", type=int, default=0, help="the network's initial weights and the batches' order")
    parser.add_argument("--threads", type=int, default=2, help="PyTorch threads")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=JSON",
                        help="override a detector parameter of the set-up in every scan (repeatable)")
    parser.add_argument("--samples", default="", help="an .npz of the samples: read if it exists, else written after "
                        "the scan (to train again, e.g. with another --seed, without scanning again)")
    args = parser.parse_args()
    try:
        import torch  # noqa: PLC0415
    except ImportError:
        raise SystemExit("this tool needs PyTorch (pip install torch); the package itself does not") from None
    torch.set_num_threads(args.threads)
    cv2.setNumThreads(1)
    scenes = training_scenes(args.train_scenes)
    det = setup_detector(parse_overrides(args.set))        # the set-up before the patch network
    cache = Path(args.samples) if args.samples else None
    if cache is not None and cache.is_file():
        with np.load(cache, allow_pickle=False) as stored:
            crops, on_counted, targets = stored["crops"], stored["on_counted"], stored["targets"]
        print(f"read {len(on_counted)} samples from {cache}")
    else:
        crops, on_counted, targets = samples(det, scenes)
        if cache is not None:
            np.savez(cache, crops=crops, on_counted=on_counted, targets=targets)
    label = labels(on_counted)
    net, loss = train(crops, label, targets, args.epochs, args.seed)
    out = Path(args.out)
    onnx = out.with_suffix(".onnx")
    torch.onnx.export(net, torch.zeros(1, 3, SIZE, SIZE), str(onnx), input_names=["patch"], output_names=["outputs"],
                      dynamic_axes={"patch": {0: "n"}, "outputs": {0: "n"}}, opset_version=11, dynamo=False)
    info = {"train_seeds": [s for s, _ in scenes], "samples": int(len(label)), "vehicles": int((label == 1).sum()),
            "background": int((label == 0).sum()), "left_out": int((label == -1).sum()), "epochs": args.epochs,
            "seed": args.seed, "final_loss": round(loss, 5), "cascade": Path(det.config.model).name,
            "verifier": Path(det.config.verifier).name, "box_regressor": Path(det.config.box_regressor).name,
            "min_neighbors": det.config.min_neighbors, "window_margin": det.config.window_margin,
            "command": "python tools/train_uav_patch_net.py " + " ".join(sys.argv[1:])}
    out.write_text(json.dumps(header(onnx.name, SIZE, GROW, info), indent=1) + "\n")
    PatchNet.load(out)           # the graph runs in OpenCV as the detector will run it
    print(f"wrote {out} and {onnx}: {info['vehicles']} vehicle / {info['background']} background groups "
          f"({info['left_out']} left out)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
