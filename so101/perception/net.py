"""The eyes' network (PyTorch: it runs in the policy environment, `so101 policy-env`): a small fully
convolutional net that, from the front picture, maps where the cube, the box and the gripper's tip are
(a heat map each, a quarter of the picture's size, with the sub-cell offset of each) and, at the cube, its yaw (as the
cosine and sine of four times it: a cube looks the same every quarter turn) and its height above the
floor. A map, not one regression of coordinates: the same filters find the cube anywhere in the
picture, so a few hundred demonstrations' layouts teach every place (a regression memorized them).
"""

from __future__ import annotations

import torch
from torch import nn

from so101.perception.estimate import KEYPOINTS  # the maps' order, read there without torch

CHANNELS = (*KEYPOINTS, *(f"{name}_{axis}" for name in KEYPOINTS for axis in ("du", "dv")), "cos4yaw", "sin4yaw", "lift")


def _block(inputs: int, outputs: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(inputs, outputs, 3, stride, padding=dilation, dilation=dilation, bias=False),
                         nn.BatchNorm2d(outputs), nn.ReLU(inplace=True))


class EyesNet(nn.Module):
    """Pictures (B, 3, H, W) as uint8 or 0-255 floats -> maps (B, len(CHANNELS), H / 4, W / 4)."""

    def __init__(self, width: int = 32):
        super().__init__()
        self.fine = nn.Sequential(_block(3, width // 2, 2), _block(width // 2, width, 2), _block(width, width))
        self.coarse = nn.Sequential(_block(width, 2 * width, 2), _block(2 * width, 2 * width, dilation=2),
                                    _block(2 * width, 2 * width, dilation=4))
        self.up = nn.Upsample(scale_factor=2, mode="bilinear", align_corners=False)
        self.head = nn.Sequential(_block(3 * width, 48), nn.Conv2d(48, len(CHANNELS), 1))

    def forward(self, pictures: torch.Tensor) -> torch.Tensor:
        x = (pictures.float() / 255.0 - 0.5) / 0.25
        fine = self.fine(x)
        coarse = self.up(self.coarse(fine))
        maps: torch.Tensor = self.head(torch.cat([fine, coarse[..., :fine.shape[-2], :fine.shape[-1]]], dim=1))
        return maps
