"""Training samples from capture directories: normalisation, misalignment, random crops.

Normalisation (recorded in every exported ``model.json``; the daemon applies the same):

- RGB: ``/ 255`` → [0, 1];
- amplitude: ``I = I_raw ⊙ D²`` (undoes the 1/D² fall-off, leaving something like IR albedo,
  which looks like the RGB image and so can be matched to it), divided by its
  ``amplitude_percentile``-th percentile over valid-depth pixels and clipped to [0, 1]; a
  percentile, not the maximum, so that a few specular pixels do not darken the whole image;
- depth: metres ``/ max_depth`` (10 m: beyond any indoor ToF module's unambiguous range at the
  usual modulation frequencies, so no valid depth saturates).

Sample kinds, by the frame's ``perturbation`` in ``capture.json``:

- zero (an *aligned* frame) with augmentation on: a random misalignment is synthesised
  (:mod:`dear_train.augmentation`);
- zero with augmentation off: used as is, flow 0;
- non-zero (a misaligned frame): the ground-truth flow is the ``.flow.flo`` file if present,
  else ``perturbation.flow_at(gt_depth)``;
- absent (unknown misalignment) or no ground-truth depth: not usable for supervised training;
  skipped and counted (:attr:`DearDataset.skipped`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from dear_train.augmentation import AugmentConfig, augment, draw_perturbation
from dear_train.data.capture import Capture, Frame

#: Inputs to the networks must be multiples of this (see ``models.INPUT_SIZE_MULTIPLE``).
SIZE_MULTIPLE = 8


@dataclass(frozen=True)
class Normalisation:
    """The constants that turn sensor data into network inputs (see the module docstring)."""

    max_depth: float = 10.0
    amplitude_percentile: float = 99.0

    def to_dict(self) -> dict:
        return asdict(self)


def normalize_amplitude(amp_raw: np.ndarray, depth: np.ndarray, percentile: float) -> np.ndarray:
    """``clip(I_raw·D² / percentile(I_raw·D² over valid D), 0, 1)`` as float32."""
    valid = np.isfinite(depth) & (depth > 0)
    i = np.where(valid, amp_raw.astype(np.float32) * np.where(valid, depth, 0) ** 2, 0)
    scale = float(np.percentile(i[valid], percentile)) if valid.any() else 0.0
    if not scale > 0:
        return np.zeros_like(i, dtype=np.float32)
    return np.clip(i / scale, 0.0, 1.0).astype(np.float32)


def usable(frame_perturbation: object, has_gt: bool) -> bool:
    """Whether a frame can supervise training (known misalignment and ground-truth depth)."""
    return frame_perturbation is not None and has_gt


def make_sample(
    frame: Frame,
    norm: Normalisation,
    augment_cfg: AugmentConfig | None,
    rng: np.random.Generator,
    classical: bool = False,
) -> dict[str, np.ndarray]:
    """Full-frame training sample as float32 ``(C, H, W)`` arrays (see the module docstring).

    Keys: ``rgb`` [0, 1] on the RGB grid; ``amplitude`` normalised and ``tof_depth`` metres on
    the ToF grid; ``gt_depth`` metres on the RGB grid; ``flow`` RGB→ToF px and ``flow_valid``;
    with ``classical``, ``tof_classical``: the classical refiner's output (metres, ToF grid).
    """
    if classical and frame.classical is None:
        raise ValueError(
            f"frame {frame.id}: no classical.png (add the classical refiner's planes with "
            "`dear-synth classical --capture DIR`)"
        )
    if frame.gt_depth is None or frame.perturbation is None:
        raise ValueError(f"frame {frame.id}: needs ground-truth depth and a known perturbation")
    tof_depth = frame.depth.copy()
    if frame.mask is not None:
        tof_depth[~frame.mask] = 0.0
    p = frame.perturbation
    aligned = p.tx == 0 and p.ty == 0 and p.cx == 0 and p.cy == 0
    if aligned and augment_cfg is not None:
        h, w = tof_depth.shape
        view = augment(frame.rgb, frame.gt_depth, draw_perturbation(rng, h, w, augment_cfg))
        rgb, gt = view.rgb, view.depth
        flow = np.stack([view.flow_u, view.flow_v])
        valid = view.valid
    else:
        rgb, gt = frame.rgb, frame.gt_depth
        if frame.flow is not None:
            flow = frame.flow
            valid = np.isfinite(flow).all(axis=0) & (gt > 0)
        else:
            u, v, valid = p.flow_at(gt)
            flow = np.stack([u, v])
    sample = {
        "rgb": (rgb.astype(np.float32) / 255.0).transpose(2, 0, 1),
        "amplitude": normalize_amplitude(frame.amplitude, tof_depth, norm.amplitude_percentile)[
            None
        ],
        "tof_depth": tof_depth[None].astype(np.float32),
        "gt_depth": np.where(valid, gt, 0).astype(np.float32)[None],
        "flow": np.where(valid, flow, 0).astype(np.float32),
        "flow_valid": valid[None],
    }
    if classical:
        # Not masked: the classical filter ran on the masked depth and filled what it could,
        # as it does in the daemon.
        assert frame.classical is not None
        sample["tof_classical"] = frame.classical[None].astype(np.float32)
    return sample


def crop_sample(
    sample: dict[str, np.ndarray], size: tuple[int, int], rng: np.random.Generator | None
) -> dict[str, np.ndarray]:
    """Crop every array to ``size`` = (h, w): at random with ``rng``, else centred.

    RGB and ToF grids are cropped with the same window, so flows keep their meaning.
    """
    h, w = sample["tof_depth"].shape[-2:]
    ch, cw = size
    if ch > h or cw > w:
        raise ValueError(f"crop {ch}×{cw} is larger than the frame {h}×{w}")
    if rng is None:
        y0, x0 = (h - ch) // 2, (w - cw) // 2
    else:
        y0 = int(rng.integers(0, h - ch + 1))
        x0 = int(rng.integers(0, w - cw + 1))
    return {k: np.ascontiguousarray(v[..., y0 : y0 + ch, x0 : x0 + cw]) for k, v in sample.items()}


def evaluation_size(h: int, w: int) -> tuple[int, int]:
    """The largest size ≤ ``(h, w)`` that the networks accept."""
    return h // SIZE_MULTIPLE * SIZE_MULTIPLE, w // SIZE_MULTIPLE * SIZE_MULTIPLE


class DearDataset(Dataset):
    """Samples from one or more capture directories.

    Args:
        roots: capture directories.
        crop: ``(h, w)`` random crop (multiples of 8); ``None`` → centred crop to the largest
            multiple of 8 (evaluation).
        augment: perturbation ranges for aligned frames, or ``None``.
        norm: normalisation constants.
        seed: base seed; sample ``i`` in epoch ``e`` uses ``(seed, e, i)`` so runs reproduce
            and every epoch draws new misalignments.
        items: restrict to these ``(capture index, frame index)`` pairs (train/val split).
        classical: also load the classical refiner's planes (``tof_classical``), for refiners
            that take them; a frame without one is an error naming it.
    """

    def __init__(
        self,
        roots: list[str | Path],
        crop: tuple[int, int] | None = None,
        augment: AugmentConfig | None = None,
        norm: Normalisation | None = None,
        seed: int = 0,
        items: list[tuple[int, int]] | None = None,
        classical: bool = False,
    ) -> None:
        if crop is not None and (crop[0] % SIZE_MULTIPLE or crop[1] % SIZE_MULTIPLE):
            raise ValueError(f"crop {crop} must be multiples of {SIZE_MULTIPLE}")
        self.captures = [Capture(r) for r in roots]
        self.crop = crop
        self.augment = augment
        self.norm = norm or Normalisation()
        self.seed = seed
        self.classical = classical
        self.epoch = 0
        self.skipped = 0
        if items is None:
            items = []
            for ci, cap in enumerate(self.captures):
                for fi, entry in enumerate(cap.manifest.frames):
                    gt = cap.root / "frames" / f"{entry.id:06d}.gt.png"
                    if usable(entry.perturbation, gt.exists()):
                        items.append((ci, fi))
                    else:
                        self.skipped += 1
        if not items:
            raise ValueError(
                f"no usable frames in {', '.join(map(str, roots))} (frames need gt depth and a "
                f"known perturbation; {self.skipped} skipped)"
            )
        self.items = items

    def set_epoch(self, epoch: int) -> None:
        """Select the random draws of ``epoch`` (call before each epoch)."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        ci, fi = self.items[index]
        rng = np.random.default_rng([self.seed, self.epoch, index])
        frame = self.captures[ci].load(fi)
        try:
            sample = make_sample(frame, self.norm, self.augment, rng, self.classical)
        except ValueError as e:
            raise ValueError(f"{self.captures[ci].root}: {e}") from e
        if self.crop is not None:
            sample = crop_sample(sample, self.crop, rng)
        else:
            sample = crop_sample(sample, evaluation_size(*frame.depth.shape), None)
        return {k: torch.from_numpy(v) for k, v in sample.items()}


def split_items(
    dataset: DearDataset, val_fraction: float, seed: int
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Deterministic train/validation split of ``dataset.items`` (at least one of each when
    there are two or more frames)."""
    items = list(dataset.items)
    order = np.random.default_rng(seed).permutation(len(items))
    n_val = round(len(items) * val_fraction)
    n_val = min(max(n_val, 1), len(items) - 1) if len(items) >= 2 else 0
    val = [items[i] for i in sorted(order[:n_val])]
    train = [items[i] for i in sorted(order[n_val:])]
    return train, val or train
