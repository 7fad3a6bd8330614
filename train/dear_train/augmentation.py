"""Multi-view augmentation (DEAR §4.3): synthesise misaligned samples from aligned ones.

From an aligned sample — RGB, ToF amplitude, ToF depth and ground-truth depth, all on one grid —
draw a perturbation ``P``: ``c ~ U(±2.5 %`` of the image size) per axis and
``t ~ U(±30 %`` of the largest baseline ``tx_max = f·b_max``) per axis. Every ToF pixel ``q``
with ground-truth depth ``z`` then lands at ``q − P.flow_at(z)`` in a virtual RGB view; the RGB
image and the ground-truth depth are forward-splatted there with a z-buffer
(:func:`dear_train.geometry.synthesize_view`, identical to the Rust pipeline's), and the
supervising RGB→ToF flow is ``W(p) = P.flow_at(z_rgb(p))`` on the new RGB grid. The ToF
amplitude and depth stay where they are: the network must learn to find them.

The augmentation is done on the fly with a per-sample random generator, so every epoch sees new
misalignments of the same scenes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dear_train.geometry import Calibration, SynthesizedView, synthesize_view


@dataclass(frozen=True)
class AugmentConfig:
    """Ranges of the random perturbation."""

    #: ``c_x ~ U(±c_frac·W)``, ``c_y ~ U(±c_frac·H)``.
    c_frac: float = 0.025
    #: ``t_x, t_y ~ U(±t_frac·tx_max)``.
    t_frac: float = 0.30
    #: The largest baseline of the modules the model is for, ``f·b_max`` in px·m. The default
    #: is a phone-class module: f ≈ 500 px at VGA and a ToF–RGB baseline of up to 2 cm.
    tx_max: float = 10.0

    def to_dict(self) -> dict:
        return asdict(self)


def draw_perturbation(
    rng: np.random.Generator, height: int, width: int, cfg: AugmentConfig
) -> Calibration:
    """One random perturbation for an ``height × width`` image."""
    t = cfg.t_frac * cfg.tx_max
    return Calibration(
        tx=float(rng.uniform(-t, t)),
        ty=float(rng.uniform(-t, t)),
        cx=float(rng.uniform(-cfg.c_frac * width, cfg.c_frac * width)),
        cy=float(rng.uniform(-cfg.c_frac * height, cfg.c_frac * height)),
    )


def augment(rgb: np.ndarray, gt_depth: np.ndarray, perturbation: Calibration) -> SynthesizedView:
    """The RGB view and ground truth for ``perturbation`` (see the module docstring).

    ``rgb`` ``(H, W, 3)`` uint8 and ``gt_depth`` ``(H, W)`` metres are on the ToF grid. The
    returned ``flow_u``/``flow_v`` are the supervising RGB→ToF flow, valid where ``valid``.
    """
    return synthesize_view(rgb, gt_depth, perturbation)
