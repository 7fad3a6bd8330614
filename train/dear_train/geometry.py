"""Geometry of the RGB↔ToF alignment, in PyTorch (training) and NumPy (data synthesis).

Conventions (identical to the Rust crate ``dear-pipeline``, checked by ``tests/test_rust_parity.py``
against the shared vectors in ``fixtures/geometry/``):

- images are row-major ``(row, column)``; pixel centres sit at integer coordinates;
- a flow ``W`` lives on the grid of the image being *produced* (the RGB grid): channel 0 is
  ``u`` (along columns, x), channel 1 is ``v`` (along rows, y); RGB pixel ``p`` sees the ToF
  pixel ``p + W(p)``;
- the weak calibration is ``(tx, ty, cx, cy)``: ``W(p) = (tx / z(p) + cx, ty / z(p) + cy)`` with
  ``t`` in px·m (the focal length is absorbed), ``c`` in px and ``z`` in metres;
- depth ``0`` (or any non-positive / non-finite value) means "no measurement";
- a backward-warp sample point outside the convex hull of the source's pixel centres,
  ``0 ≤ x ≤ w−1`` and ``0 ≤ y ≤ h−1``, is *invalid*: it yields 0 **and** a false validity
  mask, never a clamped border value nor a zero that a loss would read as a depth.

Batched torch tensors are ``(N, C, H, W)``; calibrations are ``(N, 4)`` tensors in the order
``(tx, ty, cx, cy)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

#: Relative part of the same-surface tolerance (``dear-pipeline`` ``DEPTH_EDGE_REL``): two depths
#: within 3 % of the nearer one are one surface; object boundaries are tens of percent apart.
DEPTH_EDGE_REL = 0.03
#: Absolute floor of the same-surface tolerance in metres (``DEPTH_EDGE_ABS_M``): at close range
#: 3 % falls below the sensor's ~1 cm noise.
DEPTH_EDGE_ABS_M = 0.01


@dataclass(frozen=True)
class Calibration:
    """The weak calibration ``W(p) = (tx / z + cx, ty / z + cy)`` (px·m, px·m, px, px)."""

    tx: float = 0.0
    ty: float = 0.0
    cx: float = 0.0
    cy: float = 0.0

    def flow_at(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(u, v, valid)`` for depths ``z`` in metres; invalid depths give ``u = v = 0``."""
        z = np.asarray(z, dtype=np.float32)
        valid = np.isfinite(z) & (z > 0)
        zs = np.where(valid, z, np.float32(1.0))
        u = np.where(valid, np.float32(self.tx) / zs + np.float32(self.cx), np.float32(0.0))
        v = np.where(valid, np.float32(self.ty) / zs + np.float32(self.cy), np.float32(0.0))
        return u.astype(np.float32), v.astype(np.float32), valid

    def as_tensor(self) -> torch.Tensor:
        """``(4,)`` float32 tensor ``(tx, ty, cx, cy)``."""
        return torch.tensor([self.tx, self.ty, self.cx, self.cy], dtype=torch.float32)

    @staticmethod
    def from_dict(d: dict) -> Calibration:
        """From the JSON object ``{"tx", "ty", "cx", "cy"}`` used by captures and fixtures."""
        return Calibration(float(d["tx"]), float(d["ty"]), float(d["cx"]), float(d["cy"]))

    def to_dict(self) -> dict[str, float]:
        return {"tx": self.tx, "ty": self.ty, "cx": self.cx, "cy": self.cy}


def valid_depth(depth: torch.Tensor) -> torch.Tensor:
    """Boolean mask of measured depths (positive and finite)."""
    return torch.isfinite(depth) & (depth > 0)


def flow_from_depth(calib: torch.Tensor, depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Flow ``(N, 2, H, W)`` predicted by ``calib`` ``(N, 4)`` at depths ``(N, 1, H, W)`` metres.

    Returns ``(flow, valid)``; where the depth is invalid the flow is 0 and ``valid`` false.
    """
    valid = valid_depth(depth)
    safe = torch.where(valid, depth, torch.ones_like(depth))
    t = calib[:, 0:2, None, None]
    c = calib[:, 2:4, None, None]
    flow = torch.where(valid, t / safe + c, torch.zeros_like(t / safe))
    return flow, valid


def _inverse_depth(depth: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """``1 / depth`` where valid, 0 elsewhere (no inf/NaN reaches the sums or their gradients)."""
    return torch.where(valid, 1.0 / torch.where(valid, depth, torch.ones_like(depth)), 0.0)


def _usable_weights(
    flow: torch.Tensor, depth: torch.Tensor, weights: torch.Tensor | None
) -> torch.Tensor:
    """Per-pixel weight ``(N, 1, H, W)``: the caller's (a bool mask counts as 0/1), zeroed where
    the depth is invalid, the flow is not finite or the weight is not positive and finite."""
    ok = valid_depth(depth) & torch.isfinite(flow).all(dim=1, keepdim=True)
    w = torch.ones_like(depth) if weights is None else weights.to(depth.dtype)
    ok = ok & torch.isfinite(w) & (w > 0)
    return torch.where(ok, w, torch.zeros_like(w))


def _fit(flow: torch.Tensor, a: torch.Tensor, w: torch.Tensor, ridge: float) -> torch.Tensor:
    """Centred weighted line fit ``W ≈ t·a + c`` on both axes; returns ``(N, 4)``.

    ``t = Σw(a−ā)(W−W̄) / Σw(a−ā)²``, ``c = W̄ − t·ā`` (the form ``dear-pipeline`` uses: centring
    first avoids the cancellation of the raw normal equations when depths are similar). The
    denominator gets ``ridge · Σw · ā²``: negligible for any separable problem, and for a
    fronto-parallel plane (where ``t`` and ``c`` cannot be told apart) it shrinks ``t`` towards
    0 instead of dividing by ~0, which keeps end-to-end training finite.
    """
    dims = (2, 3)
    flow = torch.where(w > 0, flow, torch.zeros_like(flow))
    sw = w.sum(dims).clamp_min(1e-30)  # (N, 1)
    mean_a = (w * a).sum(dims) / sw  # (N, 1)
    mean_w = (w * flow).sum(dims) / sw  # (N, 2)
    da = a - mean_a[:, :, None, None]
    saa = (w * da * da).sum(dims) + ridge * sw * mean_a * mean_a + 1e-30  # (N, 1)
    sa_w = (w * da * (flow - mean_w[:, :, None, None])).sum(dims)  # (N, 2)
    t = sa_w / saa
    c = mean_w - t * mean_a
    return torch.cat([t, c], dim=1)


def solve_calibration(
    flow: torch.Tensor,
    depth: torch.Tensor,
    weights: torch.Tensor | None = None,
    ridge: float = 1e-8,
) -> torch.Tensor:
    """The paper's per-axis least squares for the weak calibration, differentiable.

    Minimises ``Σ_p w(p) (W(p) − (t / D(p) + c))²`` independently per axis: with ``a = 1/D``
    it is the line fit ``W ≈ t·a + c``, solved in closed form (the 2×2 normal equations,
    centred, see :func:`_fit`) so gradients flow from ``(t, c)`` back into the flow and the
    depth during end-to-end training. Pixels with invalid depth, non-finite flow or
    non-positive weight are skipped, as in ``dear-pipeline``'s ``solve_calibration``.

    Args:
        flow: ``(N, 2, H, W)`` px.
        depth: ``(N, 1, H, W)`` metres (``D_rgb``, the depth seen on the RGB grid).
        weights: optional ``(N, 1, H, W)`` per-pixel weights or bool mask.
        ridge: relative regularisation of degenerate fits (see :func:`_fit`).

    Returns:
        ``(N, 4)`` ``(tx, ty, cx, cy)``.
    """
    w = _usable_weights(flow, depth, weights)
    return _fit(flow, _inverse_depth(depth, w > 0), w, ridge)


def solve_calibration_robust(
    flow: torch.Tensor,
    depth: torch.Tensor,
    weights: torch.Tensor | None = None,
    huber_delta_px: float = 1.0,
    iterations: int = 20,
    ridge: float = 1e-8,
) -> torch.Tensor:
    """Huber-weighted iteratively reweighted least squares, as ``dear-pipeline`` does it.

    Used in evaluation, where a few grossly wrong flow vectors (occlusions, flying pixels)
    must not drag the estimate. Starting from the plain fit, each iteration multiplies the
    caller's weight by ``min(1, δ / r)`` with ``r`` the current *end-point* residual (a wrong
    flow vector is usually wrong in both components, so both axes drop it together); a batch
    item stops once the predicted flow at its smallest and largest inverse depth moves by
    < 1e-5 px.
    """
    w0 = _usable_weights(flow, depth, weights)
    a = _inverse_depth(depth, w0 > 0)
    calib = _fit(flow, a, w0, ridge)
    big = torch.tensor(float("inf"), dtype=a.dtype, device=a.device)
    a_min = torch.where(w0 > 0, a, big).flatten(1).min(dim=1).values
    a_max = torch.where(w0 > 0, a, -big).flatten(1).max(dim=1).values
    active = torch.ones(flow.shape[0], dtype=torch.bool, device=flow.device)
    for _ in range(iterations):
        pred = calib[:, 0:2, None, None] * a + calib[:, 2:4, None, None]
        r = torch.linalg.vector_norm(flow - pred, dim=1, keepdim=True)
        w = w0 * torch.where(r > huber_delta_px, huber_delta_px / r.clamp_min(1e-30), 1.0)
        nxt = _fit(flow, a, w, ridge)
        d = nxt - calib
        change = torch.maximum(
            torch.hypot(d[:, 0] * a_min + d[:, 2], d[:, 1] * a_min + d[:, 3]),
            torch.hypot(d[:, 0] * a_max + d[:, 2], d[:, 1] * a_max + d[:, 3]),
        )
        calib = torch.where(active[:, None], nxt, calib)
        active = active & ~(change < 1e-5)
        if not bool(active.any()):
            break
    return calib


def rms_residual(
    calib: torch.Tensor,
    flow: torch.Tensor,
    depth: torch.Tensor,
    weights: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Weighted RMS end-point residual (px) of ``calib`` and the number of pixels used."""
    w = _usable_weights(flow, depth, weights)
    pred, _ = flow_from_depth(calib, depth)
    r2 = ((flow - pred) ** 2).sum(dim=1, keepdim=True)
    r2 = torch.where(w > 0, r2, torch.zeros_like(r2))
    dims = (1, 2, 3)
    rms = ((w * r2).sum(dims) / w.sum(dims).clamp_min(1e-30)).sqrt()
    return rms, (w > 0).sum(dims)


def convt_flow(
    calib: torch.Tensor, depth: torch.Tensor, fallback: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``W_convt = (tx / D + cx, ty / D + cy)`` where ``D`` is valid, ``fallback`` elsewhere.

    The fallback (``W_rough`` in DEAR) gives the fusion net a sensible value where the warped
    depth has holes, instead of the 0 or infinity that ``1 / 0`` would produce. The daemon does
    the same (see README, "Graph I/O contract").
    """
    flow, valid = flow_from_depth(calib, depth)
    return torch.where(valid, flow, fallback), valid


def _sample_points(flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    _n, _, h, w = flow.shape
    ys = torch.arange(h, dtype=flow.dtype, device=flow.device).view(1, h, 1)
    xs = torch.arange(w, dtype=flow.dtype, device=flow.device).view(1, 1, w)
    return xs + flow[:, 0], ys + flow[:, 1]


def inside_hull(sx: torch.Tensor, sy: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """Sample points inside the convex hull of an ``h × w`` image's pixel centres (NaN → False)."""
    return (sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)


def warp_bilinear(src: torch.Tensor, flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Backward warp ``out(p) = src(p + W(p))`` with bilinear interpolation and a validity mask.

    Uses ``grid_sample`` (``align_corners=True`` puts pixel centres at integer coordinates, the
    project's convention). Points outside the source's hull give 0 and ``valid = False``: the
    losses exclude them instead of learning from a fabricated zero. Training only: exported
    graphs never contain ``grid_sample`` (the daemon warps).

    Args:
        src: ``(N, C, Hs, Ws)``.
        flow: ``(N, 2, H, W)`` on the output grid.

    Returns:
        ``(out (N, C, H, W), valid (N, 1, H, W) bool)``.
    """
    hs, ws = src.shape[-2:]
    sx, sy = _sample_points(flow)
    valid = inside_hull(sx, sy, hs, ws)
    gx = 2.0 * sx / max(ws - 1, 1) - 1.0
    gy = 2.0 * sy / max(hs - 1, 1) - 1.0
    grid = torch.stack([gx, gy], dim=-1)
    grid = torch.where(valid[..., None], grid, torch.zeros_like(grid))
    out = F.grid_sample(src, grid, mode="bilinear", padding_mode="border", align_corners=True)
    valid = valid[:, None]
    return out * valid, valid


def _taps(flow: torch.Tensor, hs: int, ws: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Flat source indices ``(N, 4, H, W)``, weights ``(N, 4, H, W)`` and inside mask.

    Tap order ``(y0,x0), (y0,x1), (y1,x0), (y1,x1)`` as in ``dear-pipeline``'s ``bilinear_taps``.
    """
    sx, sy = _sample_points(flow)
    inside = inside_hull(sx, sy, hs, ws)
    sxc = torch.where(inside, sx, torch.zeros_like(sx))
    syc = torch.where(inside, sy, torch.zeros_like(sy))
    x0 = sxc.detach().floor().clamp(0, ws - 1)
    y0 = syc.detach().floor().clamp(0, hs - 1)
    x1 = (x0 + 1).clamp(max=ws - 1)
    y1 = (y0 + 1).clamp(max=hs - 1)
    fx = sxc - x0
    fy = syc - y0
    weights = torch.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], dim=1)
    idx = torch.stack([y0 * ws + x0, y0 * ws + x1, y1 * ws + x0, y1 * ws + x1], dim=1).long()
    return idx, weights, inside


def warp_depth(src: torch.Tensor, flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Discontinuity-aware backward warp of a depth map (metres, 0 = invalid).

    Mirrors ``dear-pipeline``'s ``warp_depth``: among the four bilinear neighbours with positive
    weight and valid depth, the one with the largest weight picks the surface, and only the
    neighbours on that surface (within ``max(3 %·z, 1 cm)``) are blended with renormalised
    weights. A bilinear blend of a 1 m foreground and a 3 m background would invent a point in
    mid-air; a blend with a hole would pull the depth towards 0. Differentiable in the depth
    values and (through the weights) in the flow.

    Args:
        src: ``(N, 1, Hs, Ws)`` metres.
        flow: ``(N, 2, H, W)``.

    Returns:
        ``(depth (N, 1, H, W), valid (N, 1, H, W) bool)``.
    """
    n, _, hs, ws = src.shape
    h, w = flow.shape[-2:]
    idx, wts, inside = _taps(flow, hs, ws)
    flat = src.reshape(n, 1, hs * ws).expand(n, 4, hs * ws)
    z = torch.gather(flat, 2, idx.reshape(n, 4, h * w)).reshape(n, 4, h, w)
    ok = (wts > 0) & valid_depth(z) & inside[:, None]
    score = torch.where(ok, wts.detach(), torch.full_like(wts, -1.0))
    nearest = score.argmax(dim=1, keepdim=True)
    any_ok = ok.any(dim=1, keepdim=True)
    z_safe = torch.where(ok, z, torch.zeros_like(z))
    z_ref = torch.gather(z_safe, 1, nearest)
    tol = torch.clamp(DEPTH_EDGE_REL * z_ref.detach(), min=DEPTH_EDGE_ABS_M)
    same = ok & ((z_safe - z_ref).detach().abs() <= tol)
    wsel = wts * same
    wsum = wsel.sum(dim=1, keepdim=True)
    out = (wsel * z_safe).sum(dim=1, keepdim=True) / torch.where(
        any_ok, wsum, torch.ones_like(wsum)
    )
    out = torch.where(any_ok, out, torch.zeros_like(out))
    return out, any_ok


# --------------------------------------------------------------------------------------------
# NumPy helpers (data synthesis and augmentation run in the data loader, on the CPU).
# --------------------------------------------------------------------------------------------


def warp_depth_np(src: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """NumPy front-end of :func:`warp_depth` for ``(H, W)`` arrays."""
    flow = torch.from_numpy(np.stack([u, v]).astype(np.float32))[None]
    out, _ = warp_depth(torch.from_numpy(src.astype(np.float32))[None, None], flow)
    return out[0, 0].numpy()


def warp_bilinear_np(
    src: np.ndarray, u: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """NumPy front-end of :func:`warp_bilinear` for ``(H, W)`` or ``(H, W, C)`` arrays."""
    s = torch.from_numpy(np.asarray(src, dtype=np.float32))
    s = s[None, None] if s.dim() == 2 else s.permute(2, 0, 1)[None]
    flow = torch.from_numpy(np.stack([u, v]).astype(np.float32))[None]
    out, valid = warp_bilinear(s, flow)
    o = out[0, 0] if np.asarray(src).ndim == 2 else out[0].permute(1, 2, 0)
    return o.numpy(), valid[0, 0].numpy()


#: Splat contributions at or below this bilinear weight are dropped (``SPLAT_MIN_WEIGHT``).
SPLAT_MIN_WEIGHT = 1e-3
#: Minimum front-surface coverage for a synthesised pixel to be valid (``SPLAT_MIN_COVERAGE``).
SPLAT_MIN_COVERAGE = 0.5


@dataclass
class SynthesizedView:
    """The RGB view a perturbation produces, with its ground truth (all ``(H, W[, C])``)."""

    rgb: np.ndarray  # uint8, black where invalid
    depth: np.ndarray  # float32 metres, 0 where invalid
    flow_u: np.ndarray  # float32 px, P.flow_at(depth) where valid, 0 elsewhere
    flow_v: np.ndarray
    valid: np.ndarray  # bool


def synthesize_view(
    rgb: np.ndarray, depth: np.ndarray, perturbation: Calibration
) -> SynthesizedView:
    """Forward-splat an aligned ``(rgb, depth)`` sample into the view of ``perturbation``.

    Bit-for-bit the scheme of ``dear-pipeline``'s ``synthesize_view`` (f32 arithmetic, the same
    accumulation order): each valid source pixel ``q`` at depth ``z`` lands at
    ``q − P.flow_at(z)`` and spreads bilinear weights over the four pixels around it (weights
    ≤ 1e-3 and targets outside the image dropped). Pass 1 keeps per target the nearest landing
    depth (z-buffer); pass 2 accumulates only the contributions on that front surface
    (within ``max(3 %·z, 1 cm)``), so a foreground never blends with what it hides; pass 3
    keeps targets whose front coverage is ≥ 0.5, with weight-normalised depth and colour, and
    marks the rest (disocclusions, the border the view moved away from) invalid. Bilinear
    splatting + normalisation shifts a linear image exactly, so sub-pixel shifts are accurate.
    The returned flow is recomputed from the output depth: exactly ``P.flow_at(depth)``.

    Args:
        rgb: ``(H, W, C)`` uint8 on the ToF grid.
        depth: ``(H, W)`` float32 metres on the ToF grid (ground truth), 0 = invalid.
        perturbation: the calibration of the virtual RGB view.
    """
    depth = np.asarray(depth, dtype=np.float32)
    h, w = depth.shape
    if rgb.shape[:2] != (h, w):
        raise ValueError(f"synthesize_view: rgb is {rgb.shape[:2]} but depth is {(h, w)}")
    c = rgb.shape[2]
    fu, fv, ok = perturbation.flow_at(depth)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    sel = ok.ravel()
    z = depth.ravel()[sel]
    tx = (xs.ravel() - fu.ravel())[sel]
    ty = (ys.ravel() - fv.ravel())[sel]
    colour = rgb.reshape(-1, c)[sel].astype(np.float32)
    finite = np.isfinite(tx) & np.isfinite(ty) & (np.abs(tx) < 1e9) & (np.abs(ty) < 1e9)
    x0 = np.where(finite, np.floor(tx), np.float32(0.0)).astype(np.float32)
    y0 = np.where(finite, np.floor(ty), np.float32(0.0)).astype(np.float32)
    fx, fy = tx - x0, ty - y0
    one = np.float32(1.0)
    # (source, tap) in the source's raster order then tap order, as the Rust loops.
    wt = np.stack([(one - fx) * (one - fy), fx * (one - fy), (one - fx) * fy, fx * fy], axis=1)
    dy = np.array([0, 0, 1, 1])
    dx = np.array([0, 1, 0, 1])
    ty_i = y0.astype(np.int64)[:, None] + dy
    tx_i = x0.astype(np.int64)[:, None] + dx
    keep = (
        finite[:, None]
        & (wt > np.float32(SPLAT_MIN_WEIGHT))
        & (ty_i >= 0)
        & (tx_i >= 0)
        & (ty_i < h)
        & (tx_i < w)
    )
    src = np.broadcast_to(np.arange(z.size)[:, None], keep.shape)[keep]
    tgt = (ty_i * w + tx_i)[keep]
    wk = wt[keep].astype(np.float32)
    zk = z[src]
    zbuf = np.full(h * w, np.inf, dtype=np.float32)
    np.minimum.at(zbuf, tgt, zk)
    zf = zbuf[tgt]
    tol = np.maximum(np.float32(DEPTH_EDGE_REL) * zf, np.float32(DEPTH_EDGE_ABS_M))
    front = np.abs(zk - zf) <= tol
    tgt, wk, zk, src = tgt[front], wk[front], zk[front], src[front]
    wsum = np.zeros(h * w, dtype=np.float32)
    zsum = np.zeros(h * w, dtype=np.float32)
    csum = np.zeros((h * w, c), dtype=np.float32)
    np.add.at(wsum, tgt, wk)
    np.add.at(zsum, tgt, wk * zk)
    np.add.at(csum, tgt, wk[:, None] * colour[src])
    valid = wsum >= np.float32(SPLAT_MIN_COVERAGE)
    ws = np.where(valid, wsum, one)
    z_out = np.where(valid, zsum / ws, np.float32(0.0)).astype(np.float32)
    u, v, zok = perturbation.flow_at(z_out)
    valid = valid & zok.ravel()
    rgb_out = np.floor(csum / ws[:, None] + np.float32(0.5))
    rgb_out = np.where(valid[:, None], np.clip(rgb_out, 0, 255), 0).astype(np.uint8)
    return SynthesizedView(
        rgb=rgb_out.reshape(h, w, c),
        depth=np.where(valid, z_out, np.float32(0.0)).reshape(h, w),
        flow_u=np.where(valid, u.ravel(), np.float32(0.0)).reshape(h, w).astype(np.float32),
        flow_v=np.where(valid, v.ravel(), np.float32(0.0)).reshape(h, w).astype(np.float32),
        valid=valid.reshape(h, w),
    )
