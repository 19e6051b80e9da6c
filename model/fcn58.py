"""FCN58 (paper Table 6, Fig. 13): two plain convolutions, 56 depth-wise separable layers in five
blocks with max-pools between them, and multi-scale fusion at a third of the input resolution.

Reading of the table (it gives filters, kernels and strides only):
- Every layer is conv + batch norm + ReLU; convolutions have no bias (batch norm has one).
- A depth-wise separable layer is a 3x3 depth-wise convolution, then a 1x1 point-wise one, then
  one batch norm and ReLU.
- Residual connections add the input of each pair of layers to its output where the shapes match
  (every pair but the first of the 64 -> 128 block).
- Fusion as in FCN (Long et al., the paper's [36]): a 1x1 score layer (with bias) on Conv0, Conv1,
  Maxpool0-2 and the deepest output, each up-sampled bilinearly to Conv0's size and summed.
This gives 940,608 parameters for 8 classes and 9.55 GMACs at 1920x1080, equal to an
independent count of the same reading (docs/design.md). Output: (N, classes, ceil(H/3), ceil(W/3)).
"""

import torch
import torch.nn.functional as F
from glsynth.model.settings import MIN_SIDE
from torch import nn

BLOCKS = ((64, 8), (128, 12), (128, 12), (128, 12), (128, 12))
"""(filters, depth-wise separable layers) per block: Dconv2-9, 10-21, 22-33, 34-45, 46-57."""


def conv_bn_relu(c_in: int, c_out: int, kernel: int, stride: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, kernel, stride, kernel // 2, bias=False),
                         nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


def separable(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_in, 3, 1, 1, groups=c_in, bias=False),
                         nn.Conv2d(c_in, c_out, 1, bias=False),
                         nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


class ResidualPair(nn.Module):
    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__()
        self.layers = nn.Sequential(separable(c_in, c_out), separable(c_out, c_out))
        self.residual = c_in == c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.layers(x)
        return y + x if self.residual else y


class FCN58(nn.Module):
    def __init__(self, out_channels: int) -> None:
        super().__init__()
        if out_channels < 1:
            raise ValueError(f"out_channels = {out_channels}: give at least 1")
        self.out_channels = out_channels
        self.conv0 = conv_bn_relu(3, 16, 7, 3)
        self.conv1 = conv_bn_relu(16, 64, 7, 2)
        blocks, c_in = [], 64
        for filters, layers in BLOCKS:
            blocks.append(nn.Sequential(*[ResidualPair(c_in if i == 0 else filters, filters)
                                          for i in range(layers // 2)]))
            c_in = filters
        self.blocks = nn.ModuleList(blocks)
        # Score layers on Conv0, Conv1, Maxpool0, Maxpool1, Maxpool2 and the deepest output.
        self.scores = nn.ModuleList(nn.Conv2d(c, out_channels, 1)
                                    for c in (16, 64, 64, 128, 128, 128))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"input shape {tuple(x.shape)}: give (N, 3, H, W) RGB images")
        if min(x.shape[-2:]) < MIN_SIDE:
            raise ValueError(f"input size {tuple(x.shape[-2:])}: FCN58 needs at least "
                             f"{MIN_SIDE} px per side; resize the image up")
        c0 = self.conv0(x)
        taps = [c0, self.conv1(c0)]
        y = self.blocks[0](taps[-1])
        for block in self.blocks[1:]:
            pooled = F.max_pool2d(y, 2)
            taps.append(pooled)  # Maxpool0..3; the last is not a tap of its own
            y = block(pooled)
        taps = taps[:5] + [y]
        size = c0.shape[-2:]
        out = self.scores[0](c0)
        for score, tap in zip(self.scores[1:], taps[1:]):
            out = out + F.interpolate(score(tap), size=size, mode="bilinear",
                                      align_corners=False)
        return out


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def count_macs(model: nn.Module, height: int, width: int) -> int:
    """Multiply-accumulates of the convolutions for one (3, height, width) image."""
    macs = 0

    def hook(module: nn.Conv2d, _inputs, output: torch.Tensor) -> None:
        nonlocal macs
        k = module.kernel_size[0] * module.kernel_size[1]
        macs += output.numel() * k * module.in_channels // module.groups

    handles = [m.register_forward_hook(hook) for m in model.modules()
               if isinstance(m, nn.Conv2d)]
    was_training = model.training
    try:
        model.eval()
        with torch.no_grad():
            model(torch.zeros(1, 3, height, width))
    finally:
        for h in handles:
            h.remove()
        model.train(was_training)
    return macs
