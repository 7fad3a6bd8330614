"""Overfitting one small batch: the loss must drop at least 10× (flow) or 2× (refinement).

The refinement loss counts only pixels with a warped measurement: what is left there at the
start is the sensor's own noise and multi-path error (no holes worth the whole depth), which a
net halves on one batch within the step budget but does not cut tenfold.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from torch.utils.data import DataLoader

from dear_train.augmentation import AugmentConfig
from dear_train.data.dataset import DearDataset
from dear_train.models import build_flow, build_refine
from dear_train.models.dear import DEAR
from dear_train.training.trainer import StageLoss


def _batch(capture_dir: Path, crop: tuple[int, int]) -> dict[str, torch.Tensor]:
    ds = DearDataset([capture_dir], crop=crop, augment=AugmentConfig(), seed=0)
    return next(iter(DataLoader(ds, batch_size=2, shuffle=False)))


@pytest.mark.parametrize(
    "stage,crop,lr,factor", [("flow", (48, 64), 2e-3, 10.0), ("refine", (32, 32), 3e-3, 2.0)]
)
def test_overfit_one_batch(
    capture_dir: Path, stage: str, crop: tuple[int, int], lr: float, factor: float
) -> None:
    """Edge-tier flow net (multi-scale EPE) and ToF-KPN (L1 + λ·Sobel) on one batch."""
    torch.manual_seed(0)
    if stage == "flow":
        model = DEAR(build_flow("edge"), None, None, 10.0)
        params = model.flow.parameters()
    else:
        model = DEAR(None, None, build_refine("edge"), 10.0)
        params = model.refine.parameters()
    loss_fn = StageLoss(model, stage, "kpn")
    opt = torch.optim.Adam(params, lr=lr)
    b = _batch(capture_dir, crop)
    first = None
    best = float("inf")
    for _ in range(300):
        loss, _ = loss_fn(b)
        opt.zero_grad()
        loss.backward()
        opt.step()
        first = first if first is not None else loss.item()
        best = min(best, loss.item())
        if best < first / factor:
            break
    assert best < first / factor, f"{stage}: loss {first:.4g} → {best:.4g}"
