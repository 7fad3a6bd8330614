"""The edge tier's parameter-free matching prior finds a shift between modalities that share
edges but not intensities."""

from __future__ import annotations

import torch

from dear_train.models.matching import EdgeMatchingPrior


def _blocks(h: int, w: int, seed: int) -> torch.Tensor:
    """Piecewise-constant random rectangles (edges everywhere, like object boundaries)."""
    g = torch.Generator().manual_seed(seed)
    img = torch.zeros(1, 1, h, w)
    for _ in range(60):
        y0 = int(torch.randint(0, h - 8, (1,), generator=g))
        x0 = int(torch.randint(0, w - 8, (1,), generator=g))
        bh = int(torch.randint(6, 30, (1,), generator=g))
        bw = int(torch.randint(6, 30, (1,), generator=g))
        img[..., y0 : y0 + bh, x0 : x0 + bw] = float(torch.rand(1, generator=g))
    return img


def test_prior_recovers_a_shift_between_images_with_different_intensities() -> None:
    h, w, du, dv = 128, 192, 6, -4
    scene = _blocks(h + 32, w + 32, seed=3)
    # RGB sees the scene; the amplitude sees it shifted by (du, dv) and with other intensities
    # (1 − x: every edge keeps its place but flips polarity), so amp(p + W) ~ rgb(p), W = (du, dv).
    rgb = scene[..., 16 : 16 + h, 16 : 16 + w].expand(1, 3, h, w)
    amp = 1.0 - scene[..., 16 - dv : 16 - dv + h, 16 - du : 16 - du + w]
    prior = EdgeMatchingPrior()
    with torch.no_grad():
        flow = prior(rgb, amp)
    assert flow.shape == (1, 2, 2, 3)
    mean = flow.mean(dim=(2, 3))[0]
    assert abs(float(mean[0]) - du) < 1.5, mean
    assert abs(float(mean[1]) - dv) < 1.5, mean


def test_prior_has_one_parameter_the_softmax_temperature() -> None:
    prior = EdgeMatchingPrior()
    assert [n for n, _ in prior.named_parameters()] == ["beta"]
