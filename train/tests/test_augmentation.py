"""Multi-view augmentation invariants."""

from __future__ import annotations

import numpy as np
import torch

from dear_train.augmentation import AugmentConfig, augment, draw_perturbation
from dear_train.geometry import Calibration, warp_depth


def _block_scene(h: int = 40, w: int = 50) -> tuple[np.ndarray, np.ndarray]:
    depth = np.full((h, w), 4.0, dtype=np.float32)
    depth[10:30, 15:35] = 1.0  # foreground block
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    rgb[10:30, 15:35] = (250, 10, 10)
    return rgb, depth


def test_flow_equals_p_flow_at_depth_on_valid_pixels() -> None:
    rgb, depth = _block_scene()
    p = Calibration(tx=12.0, ty=-5.0, cx=1.3, cy=-0.7)
    view = augment(rgb, depth, p)
    u, v, ok = p.flow_at(view.depth)
    assert view.valid.mean() > 0.7
    assert np.array_equal(ok, view.valid)
    np.testing.assert_allclose(view.flow_u[view.valid], u[view.valid], rtol=0, atol=1e-5)
    np.testing.assert_allclose(view.flow_v[view.valid], v[view.valid], rtol=0, atol=1e-5)
    assert not view.flow_u[~view.valid].any() and not view.depth[~view.valid].any()


def test_z_buffer_keeps_the_nearest_surface() -> None:
    rgb, depth = _block_scene()
    # Foreground (1 m) moves by −(12 + 1) = −13 px in x; background (4 m) by −(3 + 1) = −4:
    # the block slides over background pixels, and there the block must win.
    p = Calibration(tx=12.0, ty=0.0, cx=1.0, cy=0.0)
    view = augment(rgb, depth, p)
    rows = slice(12, 28)
    # Block columns in the view: 15−13 … 34−13 = 2 … 21.
    assert np.allclose(view.depth[rows, 3:21], 1.0)
    assert (view.rgb[rows, 3:21] == (250, 10, 10)).all()
    # Right of the block: background that the block uncovered is a hole, not the block.
    assert not view.valid[rows, 23:29].any()
    assert np.allclose(view.depth[rows, 35:44], 4.0)


def test_synthesised_view_is_consistent_with_backward_warping() -> None:
    """Reading the ToF-grid ground truth at p + W(p) gives back the view's depth."""
    rgb, depth = _block_scene()
    p = Calibration(tx=6.0, ty=3.0, cx=0.4, cy=-0.6)
    view = augment(rgb, depth, p)
    flow = torch.from_numpy(np.stack([view.flow_u, view.flow_v]))[None]
    back, ok = warp_depth(torch.from_numpy(depth)[None, None], flow)
    m = view.valid & ok[0, 0].numpy()
    np.testing.assert_allclose(back[0, 0].numpy()[m], view.depth[m], atol=1e-4)


def test_perturbation_ranges() -> None:
    cfg = AugmentConfig(c_frac=0.025, t_frac=0.3, tx_max=10.0)
    rng = np.random.default_rng(0)
    ps = [draw_perturbation(rng, 480, 640, cfg) for _ in range(500)]
    tx = np.array([q.tx for q in ps])
    cx = np.array([q.cx for q in ps])
    cy = np.array([q.cy for q in ps])
    assert np.abs(tx).max() <= 3.0 and np.abs(tx).max() > 2.8
    assert np.abs(cx).max() <= 16.0 and np.abs(cx).max() > 15.0
    assert np.abs(cy).max() <= 12.0 and np.abs(cy).max() > 11.0
