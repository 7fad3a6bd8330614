"""Training losses: multi-scale flow end-point error and the depth loss of ToF-KPN.

All losses take validity masks and average over valid pixels only: invalid ToF depth (0),
pixels that a warp sampled outside the image, and disocclusions of the augmentation never
contribute, so the networks are not taught to predict fabricated zeros.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F

#: FlowNet's per-level weights for levels 6 (1/64) … 2 (1/4), coarse → fine, as in the
#: authors' code.
FLOWNET_WEIGHTS = {6: 0.32, 5: 0.08, 4: 0.02, 3: 0.01, 2: 0.005}
#: Weights of the fusion net's outputs at 1/4, 1/2 and full resolution. FlowNet's finest weight
#: for each, so that in the end-to-end sum ``L_rough + L_refn + L_depth`` the refined flow
#: counts as much as the rough flow's finest level.
FUSION_WEIGHTS = (0.005, 0.005, 0.005)
#: λ of the depth gradient term.
GRADIENT_WEIGHT = 10.0
#: Weight of the ``guarded`` refiner's harm term: each metre by which the refinement is further
#: from the truth than the measurement it was given costs this much on top of the L1 term.
HARM_WEIGHT = 1.0
#: Weight of the ``guarded`` refiner's expected-error likelihood (Laplace NLL, three maps).
ERROR_NLL_WEIGHT = 0.05

#: Sobel kernels. x: derivative along columns (positive when depth grows to the right);
#: y: along rows (positive when depth grows downwards). The authors' TF code had the y kernel's
#: sign flipped, which is harmless for |∇D − ∇D_gt| only when both use the same wrong kernel;
#: we keep the correct one so that the gradients mean what they say.
SOBEL_X = torch.tensor([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]])
SOBEL_Y = SOBEL_X.t().contiguous()


def masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of ``x`` over ``mask`` (broadcast over channels); 0 when the mask is empty."""
    m = mask.to(x.dtype).expand_as(x)
    return (x * m).sum() / m.sum().clamp_min(1.0)


def downsample_flow(
    flow: torch.Tensor, valid: torch.Tensor, factor: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Masked average of a full-resolution flow over ``factor × factor`` blocks.

    Only valid pixels enter each average (a hole must not pull the target to 0); a block is
    valid if any of its pixels is. Flow values stay in full-resolution pixels. Partial blocks
    at the border (``ceil`` sizes, as the strided convolutions produce) are included.
    """
    if factor == 1:
        return flow, valid
    v = valid.to(flow.dtype)
    num = F.avg_pool2d(flow * v, factor, ceil_mode=True)
    den = F.avg_pool2d(v, factor, ceil_mode=True)
    return num / den.clamp_min(1e-12), den > 0


def epe(pred: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean end-point error ``‖pred − gt‖₂`` over valid pixels."""
    err = torch.linalg.vector_norm(pred - gt, dim=1, keepdim=True)
    return masked_mean(err, valid)


def multiscale_flow_loss(
    preds: list[torch.Tensor],
    gt: torch.Tensor,
    valid: torch.Tensor,
    weights: list[float] | tuple[float, ...],
) -> torch.Tensor:
    """``Σ_s w_s · EPE_s``: each prediction against the masked-average-pooled ground truth.

    ``preds`` are flows in full-resolution pixels at any resolutions that divide the input by
    a power of two (coarse → fine, as the networks return them); ``weights`` pair with them.
    """
    if len(preds) != len(weights):
        raise ValueError(f"{len(preds)} predictions but {len(weights)} weights")
    total = gt.new_zeros(())
    for pred, w in zip(preds, weights, strict=True):
        factor = max(1, round(gt.shape[-1] / pred.shape[-1]))
        g, v = downsample_flow(gt, valid, factor)
        g, v = (
            g[..., : pred.shape[-2], : pred.shape[-1]],
            v[..., : pred.shape[-2], : pred.shape[-1]],
        )
        total = total + w * epe(pred, g, v)
    return total


def flownet_weights(n_outputs: int) -> list[float]:
    """Weights for a flow net's outputs (coarse → fine, the full-resolution one last, weight 0:
    it is the bilinear upsampling of the 1/4 flow, which the 1/4 term already supervises)."""
    return [FLOWNET_WEIGHTS[level] for level in range(n_outputs, 1, -1)] + [0.0]


def sobel(x: torch.Tensor) -> torch.Tensor:
    """``(N, 2, H, W)`` Sobel gradients (x, y) of ``(N, 1, H, W)``, valid in the interior."""
    k = torch.stack([SOBEL_X, SOBEL_Y])[:, None].to(x)
    return F.conv2d(x, k, padding=1)


def erode(mask: torch.Tensor) -> torch.Tensor:
    """Pixels whose whole 3×3 neighbourhood is valid (where a Sobel gradient is meaningful)."""
    m = mask.to(torch.float32)
    return -F.max_pool2d(-F.pad(m, (1, 1, 1, 1)), 3, 1) > 0.5


def depth_loss(
    pred: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor, lam: float = GRADIENT_WEIGHT
) -> torch.Tensor:
    """``mean|D − D_gt| + λ·mean|∇D − ∇D_gt|`` over valid pixels (gradients: eroded mask)."""
    loss = masked_mean((pred - gt).abs(), valid)
    if lam > 0:
        grad_valid = erode(valid)
        loss = loss + lam * masked_mean((sobel(pred) - sobel(gt)).abs(), grad_valid)
    return loss


def depth_l2_loss(pred: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Masked mean squared error (the DeepToF baseline's loss)."""
    return masked_mean((pred - gt) ** 2, valid)


def laplace_nll(err: torch.Tensor, scale: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Masked mean of the Laplace negative log-likelihood ``|e| / b + log b`` (constant dropped):
    a proper scoring rule for the scale ``b``, minimised by ``b = E[|e| | inputs]``, so a map
    trained with it predicts the expected absolute error."""
    return masked_mean(err / scale + torch.log(scale), mask)


def harm(
    refined: torch.Tensor, measured_depth: torch.Tensor, gt: torch.Tensor, mask: torch.Tensor
) -> torch.Tensor:
    """Mean over ``mask`` of how much further from the truth the refinement is than the
    measurement it was given (metres): zero wherever the refiner helps, so it charges only the
    damage a refiner does to depth the sensor already got right (issue 33's low-error quarter)."""
    return masked_mean(F.relu((refined - gt).abs() - (measured_depth - gt).abs()), mask)


def guarded_losses(
    r: dict[str, torch.Tensor],
    gt: torch.Tensor,
    depth_valid: torch.Tensor,
    measured: torch.Tensor,
    depth_term: Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor],
    harm_weight: float = HARM_WEIGHT,
) -> dict[str, torch.Tensor]:
    """The ``guarded`` refiner's loss parts (issue 33), depths in metres.

    - ``depth``: ``depth_term`` (L1 + gradient) of the hybrid refinement where a measurement
      was warped;
    - ``harm``: ``harm_weight ·`` mean of how much further from the truth the refinement is than
      the measurement, where it is (a refiner must not make good depth worse);
    - ``error``: ``ERROR_NLL_WEIGHT ·`` the Laplace NLL of each candidate's expected-error map
      (refined, measurement, classical) wherever that candidate and the truth are valid. The
      errors are detached: the maps learn to predict them, not to change the depth.
    """
    refined, d, c = r["depth_refined"], r["depth_warped"], r["depth_classical"]
    errors = r["errors"]
    e_refined = (refined - gt).abs()
    nll = (
        laplace_nll(e_refined.detach(), errors[:, 0:1], depth_valid & (refined > 0))
        + laplace_nll((d - gt).abs(), errors[:, 1:2], measured)
        + laplace_nll((c - gt).abs(), errors[:, 2:3], depth_valid & (c > 0))
    )
    return {
        "depth": depth_term(refined, gt, measured),
        "harm": harm_weight * harm(refined, d, gt, measured),
        "error": ERROR_NLL_WEIGHT * nll,
    }
