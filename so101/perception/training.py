"""Teach the eyes (so101.perception.net) from the simulator's pictures and their answers
(so101.perception.pictures). PyTorch: runs in the policy environment."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from so101.bodies.camera import TASK_FRONT_CAMERA
from so101.perception.eyes import EYES_FACTS, EYES_WEIGHTS, default_eyes_facts
from so101.perception.estimate import KEYPOINTS, LIFT_SCALE_M, STRIDE, cube_in_world, read_maps
from so101.perception.geometry import view_of
from so101.perception.net import CHANNELS, EyesNet
from so101.perception.pictures import cube_half_m, yaw_mod_quarter
from so101.tasks.cube_to_box import CUBE_TO_BOX

SIGMA_CELLS = 1.0


def load_pictures(files: list[Path]) -> dict[str, np.ndarray]:
    parts = [dict(np.load(file)) for file in files]
    return {key: np.concatenate([part[key] for part in parts]) if key != "size" else parts[0][key] for key in parts[0]}


def _targets(data: dict[str, np.ndarray], index: np.ndarray, grid: tuple[int, int]) -> dict[str, torch.Tensor]:
    rows, columns = grid
    cells_v, cells_u = np.mgrid[0:rows, 0:columns]
    out: dict[str, torch.Tensor] = {}
    for name in KEYPOINTS:
        px = data[f"{name}_px"][index] / STRIDE - 0.5  # in cell coordinates, a cell's centre at integers
        heat = np.exp(-((cells_u[None] - px[:, 0, None, None]) ** 2 + (cells_v[None] - px[:, 1, None, None]) ** 2)
                      / (2 * SIGMA_CELLS ** 2))
        inside = (px[:, 0] > -0.5) & (px[:, 0] < columns - 0.5) & (px[:, 1] > -0.5) & (px[:, 1] < rows - 0.5)
        heat /= np.maximum(heat.sum(axis=(1, 2), keepdims=True), 1e-9)
        near = ((np.abs(cells_u[None] - px[:, 0, None, None]) < 1.5) & (np.abs(cells_v[None] - px[:, 1, None, None]) < 1.5)
                & inside[:, None, None])
        out[f"{name}_heat"] = torch.from_numpy(heat.astype(np.float32))
        out[f"{name}_inside"] = torch.from_numpy(inside)
        out[f"{name}_near"] = torch.from_numpy(near)
        out[f"{name}_du"] = torch.from_numpy((px[:, 0, None, None] - cells_u[None]).astype(np.float32))
        out[f"{name}_dv"] = torch.from_numpy((px[:, 1, None, None] - cells_v[None]).astype(np.float32))
    yaw = yaw_mod_quarter(data["cube_yaw"][index])
    lift = (data["object_state"][index, 2] - cube_half_m(data)[index]) / LIFT_SCALE_M
    out["cube_reg"] = torch.from_numpy(np.stack([np.cos(4 * yaw), np.sin(4 * yaw), lift], 1).astype(np.float32))
    return out


def eyes_loss(maps: torch.Tensor, targets: dict[str, torch.Tensor]) -> torch.Tensor:
    total = maps.new_zeros(())
    for channel, name in enumerate(KEYPOINTS):
        inside = targets[f"{name}_inside"]
        if inside.any():
            logits = maps[inside, channel].flatten(1)
            total = total + -(targets[f"{name}_heat"][inside].flatten(1) * F.log_softmax(logits, 1)).sum(1).mean()
        near = targets[f"{name}_near"]
        if near.any():
            first = CHANNELS.index(f"{name}_du")
            for offset, key in ((0, "du"), (1, "dv")):
                total = total + F.smooth_l1_loss(maps[:, first + offset][near], targets[f"{name}_{key}"][near], beta=0.1)
    near = targets["cube_near"]
    if near.any():
        first = 3 * len(KEYPOINTS)
        regression = maps[:, first:first + 3].permute(0, 2, 3, 1)[near]  # (cells, 3)
        wanted = targets["cube_reg"][:, None, None, :].expand(-1, *near.shape[1:], -1)[near]
        total = total + F.smooth_l1_loss(regression, wanted, beta=0.05)
    return total


def _augment(pictures: torch.Tensor, draw: torch.Generator) -> torch.Tensor:
    """Lights and colours a little off every picture's: each channel's gain and offset, and noise."""
    batch = pictures.shape[0]
    gain = 0.75 + 0.5 * torch.rand(batch, 3, 1, 1, generator=draw)
    offset = -20 + 40 * torch.rand(batch, 1, 1, 1, generator=draw)
    noise = 4 * torch.randn(pictures.shape, generator=draw)
    return (pictures.float() * gain + offset + noise).clamp(0, 255)


def check(net: EyesNet, data: dict[str, np.ndarray], batch: int = 64) -> dict[str, float]:
    """The eyes' errors on pictures they did not learn from: pixels, and millimetres in the world
    through the task's fixed front camera (with and without the box as landmark), yaw in degrees."""
    width, height = (int(v) for v in data["size"])
    view = view_of(TASK_FRONT_CAMERA, width, height)
    net.eval()
    pixel, world, bare, yaw, lift, landmark_px = [], [], [], [], [], []
    with torch.inference_mode():
        for start in range(0, len(data["pictures"]), batch):
            pictures = torch.from_numpy(data["pictures"][start:start + batch]).permute(0, 3, 1, 2)
            for offset, maps in enumerate(net(pictures).numpy()):
                i = start + offset
                sighting = read_maps(maps)
                pixel.append(np.hypot(*(np.asarray(sighting.pixels["cube"]) - data["cube_px"][i])))
                landmark_px.append(max(np.hypot(*(np.asarray(sighting.pixels[name]) - data[f"{name}_px"][i]))
                                       for name in ("box", "tip")))
                lift.append(abs(sighting.cube_lift_m - (data["object_state"][i, 2] - cube_half_m(data)[i])))
                truth = data["object_state"][i, :3]
                world.append(np.linalg.norm(cube_in_world(sighting, view, CUBE_TO_BOX.cube, CUBE_TO_BOX.box,
                                                          data["tip_xyz"][i]) - truth))
                bare.append(np.linalg.norm(cube_in_world(sighting, view, CUBE_TO_BOX.cube, CUBE_TO_BOX.box,
                                                         landmarks=False) - truth))
                error = (sighting.cube_yaw_rad - float(yaw_mod_quarter(data["cube_yaw"][i])) + math.pi / 4) % (math.pi / 2)
                yaw.append(abs(math.degrees(error - math.pi / 4)))
    net.train()
    return {"pixel_median": float(np.median(pixel)), "mm_median": 1000 * float(np.median(world)),
            "mm_p90": 1000 * float(np.percentile(world, 90)), "mm_median_no_landmark": 1000 * float(np.median(bare)),
            "yaw_deg_median": float(np.median(yaw)), "lift_mm_median": 1000 * float(np.median(lift)),
            "landmark_pixel_median": float(np.median(landmark_px))}


def train_eyes(train: dict[str, np.ndarray], held_out: dict[str, np.ndarray] | None, out: Path, steps: int,
               batch: int = 32, lr: float = 2e-3, seed: int = 1, say: Callable[[str], None] = print) -> dict[str, float]:
    """Train for `steps` and write out/eyes.pt (the weights and what they were trained on)."""
    torch.manual_seed(seed)
    draw = torch.Generator().manual_seed(seed)
    picker = np.random.default_rng(seed)
    net = EyesNet()
    optimizer = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    # A warm-up of 5% of the steps (at least two: OneCycleLR divides by the warm-up's length less one).
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimizer, max_lr=lr, total_steps=steps,
                                                   pct_start=min(0.5, max(0.05, 2.5 / steps)))
    width, height = (int(v) for v in train["size"])
    grid = (height // STRIDE, width // STRIDE)
    started = time.monotonic()
    for step in range(1, steps + 1):
        index = picker.integers(0, len(train["pictures"]), batch)
        pictures = _augment(torch.from_numpy(train["pictures"][index]).permute(0, 3, 1, 2), draw)
        loss = eyes_loss(net(pictures), _targets(train, index, grid))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        schedule.step()
        if step % 250 == 0 or step == steps:
            line = f"eyes: step {step}/{steps}, loss {loss.item():.3f}, {time.monotonic() - started:.0f} s"
            if held_out is not None and (step % 1000 == 0 or step == steps):
                line += ", held out: " + ", ".join(f"{key} {value:.2f}" for key, value in check(net, held_out).items())
            if step % 1000 == 0 and step < steps:  # for the curve of success against training
                (out / "steps").mkdir(parents=True, exist_ok=True)
                torch.save({"state_dict": net.state_dict(), "channels": list(CHANNELS)}, out / "steps" / f"eyes-{step}.pt")
            say(line)
    out.mkdir(parents=True, exist_ok=True)
    result = check(net, held_out) if held_out is not None else {}
    torch.save({"state_dict": net.state_dict(), "channels": list(CHANNELS)}, out / EYES_WEIGHTS)
    facts = default_eyes_facts((width, height), {"steps": steps, "batch": batch, "pictures": len(train["pictures"]),
                                                 "held_out": result})
    (out / EYES_FACTS).write_text(facts.as_json(), encoding="utf-8")
    return result
