"""Photometric augmentation of training images: what a real camera does to a scene that a
renderer does not, drawn per image with plain torch operations on the training device.

The order is a camera's: the lens blurs the scene, exposure and white balance scale the linear
signal, the sensor adds noise, then the image is encoded as sRGB and compressed as JPEG. Each
augmentation acts on an image with probability 1/2, with parameters drawn uniformly from the
ranges below. Images are float32 (B, 3, H, W) in [0, 1], sRGB-encoded. Labels are unchanged:
none of these moves a pixel.
"""

import math

import torch
import torch.nn.functional as F

EXPOSURE_STOPS = 1.0
"""Exposure gain 2 ** U[-1, 1]: a stop either way."""
WHITE_BALANCE = 0.15
"""Red and blue gains relative to green, U[1 - 0.15, 1 + 0.15]."""
BLUR_SIGMA_PX = (0.3, 1.5)
"""Gaussian blur (defocus, motion, a soft lens), in pixels of the training image."""
NOISE_SHOT = (0.0, 0.01)
NOISE_READ = (0.0, 0.02)
"""Sensor noise in linear light: variance NOISE_SHOT x signal + NOISE_READ ** 2."""
JPEG_QUALITY = (30.0, 95.0)
"""JPEG quality (the IJG scale of libjpeg and OpenCV), with 4:2:0 chroma."""
PROBABILITY = 0.5

# JPEG's example quantisation tables (ITU T.81, Annex K), luminance and chrominance.
_LUMA = [16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55,
         14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51, 87, 80, 62,
         18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
         49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99]
_CHROMA = [17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99,
           24, 26, 56, 99, 99, 99, 99, 99, 47, 66, 99, 99, 99, 99, 99, 99] + [99] * 32


def srgb_to_linear(x: torch.Tensor) -> torch.Tensor:
    return torch.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(x: torch.Tensor) -> torch.Tensor:
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= 0.0031308, x * 12.92, 1.055 * x.clamp_min(1e-12) ** (1 / 2.4) - 0.055)


def gaussian_blur(images: torch.Tensor, sigma: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian blur with one sigma (pixels) per image; sigma 0 leaves it as is."""
    b, c, h, w = images.shape
    radius = max(1, math.ceil(3 * float(sigma.max())))
    x = torch.arange(-radius, radius + 1, device=images.device, dtype=images.dtype)
    s = sigma.to(images).clamp_min(1e-3).view(b, 1)
    kernel = torch.exp(-0.5 * (x / s) ** 2)
    kernel = (kernel / kernel.sum(1, keepdim=True)).repeat_interleave(c, 0)  # (b*c, k)
    flat = F.pad(images.reshape(1, b * c, h, w), (radius, radius, radius, radius),
                 mode="replicate")
    flat = F.conv2d(flat, kernel.view(b * c, 1, 1, -1), groups=b * c)
    flat = F.conv2d(flat, kernel.view(b * c, 1, -1, 1), groups=b * c)
    return flat.view(b, c, h, w)


def _dct_matrix(device: torch.device) -> torch.Tensor:
    """The 2-D orthonormal 8x8 DCT-II acting on row-major flattened blocks: kron(D, D), (64, 64)
    (one matrix product for every block instead of two per block)."""
    k = torch.arange(8, dtype=torch.float32, device=device)
    d = torch.cos((2 * k[None, :] + 1) * k[:, None] * math.pi / 16) * math.sqrt(2 / 8)
    d[0] /= math.sqrt(2)
    return torch.kron(d, d)


def quant_tables(quality: torch.Tensor) -> torch.Tensor:
    """(B, 2, 8, 8) luminance and chrominance tables of the IJG quality scale."""
    q = quality.clamp(1, 100).view(-1, 1, 1, 1)
    scale = torch.where(q < 50, 5000 / q, 200 - 2 * q)
    base = torch.tensor([_LUMA, _CHROMA], dtype=torch.float32,
                        device=quality.device).view(1, 2, 8, 8)
    return ((base * scale + 50) / 100).floor().clamp(1, 255)


def _blocks_quantised(planes: torch.Tensor, tables: torch.Tensor, dct: torch.Tensor
                      ) -> torch.Tensor:
    """8x8 blocks of (B, H, W) planes (H, W multiples of 8) through the DCT, quantisation with
    (B, 8, 8) tables and the inverse DCT."""
    b, h, w = planes.shape
    blocks = planes.view(b, h // 8, 8, w // 8, 8).permute(0, 1, 3, 2, 4).reshape(b, -1, 64)
    step = tables.reshape(b, 1, 64)
    coeff = torch.round(blocks @ dct.T / step) * step
    return (coeff @ dct).view(b, h // 8, w // 8, 8, 8).permute(0, 1, 3, 2, 4).reshape(b, h, w)


def jpeg(images: torch.Tensor, quality: torch.Tensor) -> torch.Tensor:
    """Baseline JPEG round trip at one quality per image: full-range YCbCr, 4:2:0 chroma
    (2x2 means, replicated back), 8x8 DCT quantised with the IJG-scaled tables."""
    b, _, h, w = images.shape
    ph, pw = -h % 16, -w % 16
    x = F.pad(images * 255.0, (0, pw, 0, ph), mode="replicate")
    r, g, bl = x[:, 0], x[:, 1], x[:, 2]
    y = 0.299 * r + 0.587 * g + 0.114 * bl
    cb = -0.168736 * r - 0.331264 * g + 0.5 * bl
    cr = 0.5 * r - 0.418688 * g - 0.081312 * bl
    tables = quant_tables(quality.to(images.device))
    dct = _dct_matrix(images.device)
    y = _blocks_quantised(y - 128.0, tables[:, 0], dct) + 128.0
    chroma = F.avg_pool2d(torch.stack([cb, cr], 1), 2)
    hc, wc = chroma.shape[-2:]
    chroma = F.pad(chroma, (0, -wc % 8, 0, -hc % 8), mode="replicate")
    cb, cr = (_blocks_quantised(chroma[:, i], tables[:, 1], dct)[:, :hc, :wc]
              .repeat_interleave(2, -2).repeat_interleave(2, -1) for i in (0, 1))
    rgb = torch.stack([y + 1.402 * cr, y - 0.344136 * cb - 0.714136 * cr, y + 1.772 * cb], 1)
    return (rgb.round().clamp(0, 255) / 255.0)[..., :h, :w]


def _uniform(n: int, lo: float, hi: float, generator: torch.Generator) -> torch.Tensor:
    return lo + (hi - lo) * torch.rand(n, generator=generator)


def photometric(images: torch.Tensor, names: tuple[str, ...], generator: torch.Generator
                ) -> torch.Tensor:
    """The augmentations ``names`` (settings.AUGMENTATIONS) applied to a batch; every draw
    comes from ``generator`` (a CPU generator, so a seed gives the same batch on any device)."""
    b = images.shape[0]
    device = images.device

    def chosen() -> torch.Tensor:
        return torch.rand(b, generator=generator) < PROBABILITY

    x = srgb_to_linear(images)
    if "blur" in names:
        sigma = torch.where(chosen(), _uniform(b, *BLUR_SIGMA_PX, generator), torch.zeros(b))
        if sigma.any():
            x = gaussian_blur(x, sigma)
    gain = torch.ones(b, 3)
    if "exposure" in names:
        stops = _uniform(b, -EXPOSURE_STOPS, EXPOSURE_STOPS, generator)
        gain *= torch.where(chosen(), 2.0 ** stops, torch.ones(b))[:, None]
    if "white_balance" in names:
        rb = _uniform(2 * b, 1 - WHITE_BALANCE, 1 + WHITE_BALANCE, generator).view(b, 2)
        rb = torch.where(chosen()[:, None], rb, torch.ones(b, 2))
        gain *= torch.stack([rb[:, 0], torch.ones(b), rb[:, 1]], 1)
    x = x * gain.to(device).view(b, 3, 1, 1)
    if "noise" in names:
        on = chosen()
        shot = torch.where(on, _uniform(b, *NOISE_SHOT, generator), torch.zeros(b))
        read = torch.where(on, _uniform(b, *NOISE_READ, generator), torch.zeros(b))
        z = torch.randn(x.shape, generator=generator).to(device)
        var = shot.to(device).view(b, 1, 1, 1) * x.clamp_min(0) + \
            (read.to(device) ** 2).view(b, 1, 1, 1)
        x = x + var.sqrt() * z
    out = linear_to_srgb(x)
    if "jpeg" in names:
        on = chosen()
        quality = _uniform(b, *JPEG_QUALITY, generator).round()
        if on.any():
            compressed = jpeg(out[on.to(device)], quality[on])
            out = out.clone()
            out[on.to(device)] = compressed
    return out
