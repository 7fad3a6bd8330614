"""The whole DEAR pipeline as one differentiable module (end-to-end training and evaluation).

Steps (docs/algorithm.md, "The equations and where they live"): ``W_rough = F(RGB, I)``; ``D_rgb =
D_tof ∘ W_rough``; per-axis least squares for ``(t, c)``; ``W_convt = t / D_rgb + c``; ``W_refn =
G(W_rough, W_convt)``; ``D = D_tof ∘ W_refn``, ``I ∘ W_refn``; ``D_out = KPN(I∘W, D/max_depth,
RGB)``.

The warps and the solve are the training-time torch versions from :mod:`dear_train.geometry`;
in deployment the daemon runs them in Rust between the three exported graphs.
"""

from __future__ import annotations

import torch
from torch import nn

from dear_train.geometry import convt_flow, solve_calibration, warp_bilinear, warp_depth
from dear_train.models.flownetc import FlowNetC
from dear_train.models.fusion import FusionNet
from dear_train.models.kpn import RefineNet, uses_classical


class DEAR(nn.Module):
    """Flow net + fusion net + refinement net with the geometry between them.

    Any of the three may be ``None`` when a stage trains only part of the pipeline.
    """

    def __init__(
        self,
        flow: FlowNetC | None,
        fusion: FusionNet | None,
        refine: RefineNet | None,
        max_depth: float,
    ) -> None:
        super().__init__()
        self.flow = flow
        self.fusion = fusion
        self.refine = refine
        self.max_depth = max_depth

    def align(
        self, rgb: torch.Tensor, amplitude: torch.Tensor, tof_depth: torch.Tensor
    ) -> dict[str, torch.Tensor | list[torch.Tensor]]:
        """Flow estimation: rough flow, calibration solve, fused flow (when a fusion net exists).

        ``tof_depth`` is in metres on the ToF grid; ``amplitude`` normalised on the ToF grid.
        """
        if self.flow is None:
            raise RuntimeError("align() needs a flow net")
        flows_rough = self.flow(rgb, amplitude)
        w_rough = flows_rough[-1]
        out: dict[str, torch.Tensor | list[torch.Tensor]] = {
            "flows_rough": flows_rough,
            "flow_rough": w_rough,
        }
        if self.fusion is not None:
            d_rgb, _ = warp_depth(tof_depth, w_rough)
            calib = solve_calibration(w_rough, d_rgb)
            w_convt, _ = convt_flow(calib, d_rgb, w_rough)
            flows_refn = self.fusion(w_rough, w_convt)
            out.update(
                calib=calib, flow_convt=w_convt, flows_refn=flows_refn, flow_refn=flows_refn[-1]
            )
        return out

    def refine_depth(
        self,
        rgb: torch.Tensor,
        amplitude: torch.Tensor,
        tof_depth: torch.Tensor,
        flow: torch.Tensor,
        tof_classical: torch.Tensor | None = None,
    ) -> dict[str, torch.Tensor]:
        """Warp ToF depth and amplitude with ``flow`` and refine; depths in metres.

        ``tof_classical``: the classical refiner's output on the ToF grid (metres), for
        refiners that take it (``hybrid``); warped like the depth. The daemon runs the classical
        filter on the warped depth instead; at the true calibration of an aligned frame the
        two agree, and elsewhere the warp only moves the filtered surfaces.
        """
        if self.refine is None:
            raise RuntimeError("refine_depth() needs a refinement net")
        d_w, d_valid = warp_depth(tof_depth, flow)
        a_w, _ = warp_bilinear(amplitude, flow)
        c_w = None
        if tof_classical is not None and uses_classical(self.refine.variant):
            c_w = warp_depth(tof_classical, flow)[0] / self.max_depth
        if self.refine.variant == "guarded":
            # Published depth, plus what the guarded variant's losses need (metres).
            g = self.refine.forward_guarded(a_w, d_w / self.max_depth, rgb, c_w)
            assert c_w is not None  # checked by forward_guarded
            return {
                "depth_warped": d_w,
                "depth_warped_valid": d_valid,
                "depth": g["depth"] * self.max_depth,
                "depth_refined": g["refined"] * self.max_depth,
                "depth_classical": c_w * self.max_depth,
                "errors": g["errors"] * self.max_depth,
            }
        d_out = self.refine(a_w, d_w / self.max_depth, rgb, c_w) * self.max_depth
        return {"depth_warped": d_w, "depth_warped_valid": d_valid, "depth": d_out}

    def forward(
        self,
        rgb: torch.Tensor,
        amplitude: torch.Tensor,
        tof_depth: torch.Tensor,
        tof_classical: torch.Tensor | None = None,
    ) -> dict[str, torch.Tensor | list[torch.Tensor]]:
        """The full pipeline: :meth:`align` then :meth:`refine_depth` with the final flow."""
        out = self.align(rgb, amplitude, tof_depth)
        flow = out.get("flow_refn", out["flow_rough"])
        assert isinstance(flow, torch.Tensor)
        out.update(self.refine_depth(rgb, amplitude, tof_depth, flow, tof_classical))
        return out
