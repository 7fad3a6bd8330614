"""Checkpoints: resumable training state and the final model file.

``last.pt`` (written after every epoch) holds everything needed to resume: the profile, the
position in the schedule, the three nets, the optimiser and scheduler state and the history.
``final.pt`` holds the trained nets, the profile and the validation metrics; ``dear-export``
and ``dear-evaluate`` read it.
"""

from __future__ import annotations

import os
from pathlib import Path

import torch

from dear_train.models import build_flow, build_fusion, build_refine
from dear_train.models.dear import DEAR
from dear_train.training.config import Profile


def build_model(profile: Profile) -> DEAR:
    """The untrained DEAR model of a profile (tier and refinement variant)."""
    return DEAR(
        build_flow(profile.tier),
        build_fusion(profile.tier),
        build_refine(profile.tier, profile.variant),
        profile.norm.max_depth,
    )


def save_atomic(obj: dict, path: Path) -> None:
    """``torch.save`` to a temporary file then rename: a crash never leaves half a checkpoint."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def load(path: Path) -> dict:
    """Load a checkpoint dict on the CPU."""
    if not Path(path).exists():
        raise FileNotFoundError(f"{path}: no such checkpoint")
    return torch.load(path, map_location="cpu", weights_only=False)


def training_state(
    profile: Profile,
    data: list[Path],
    model: DEAR,
    stage_index: int,
    next_epoch: int,
    optimizer: dict,
    scheduler: dict,
    history: list[dict],
) -> dict:
    """The contents of ``last.pt``: everything a run needs to resume at ``(stage, epoch)``."""
    return {
        "profile": profile.to_dict(),
        "data": [str(d) for d in data],
        "model": model.state_dict(),
        "stage_index": stage_index,
        "next_epoch": next_epoch,
        "optimizer": optimizer,
        "scheduler": scheduler,
        "history": history,
    }


def final_state(
    profile: Profile,
    data: list[Path],
    model: DEAR,
    frames: dict[str, int],
    history: list[dict],
    **extra: object,
) -> dict:
    """The contents of ``final.pt``; its ``metrics`` are the last epoch's validation."""
    return {
        "profile": profile.to_dict(),
        "data": [str(d) for d in data],
        "frames": frames,
        "model": model.state_dict(),
        "metrics": history[-1]["val"] if history else {},
        "history": history,
        **extra,
    }


def load_resumable(path: Path, profile: Profile) -> dict:
    """``last.pt`` of a run of ``profile``; refuses one written by another profile."""
    ckpt = load(path)
    if ckpt["profile"] != profile.to_dict():
        raise ValueError(f"{path}: was written by a different profile; use a new --out")
    return ckpt


def load_model(path: Path) -> tuple[DEAR, Profile]:
    """The trained model and its profile from ``final.pt`` or ``last.pt``."""
    ckpt = load(path)
    profile = Profile.from_dict(ckpt["profile"])
    model = build_model(profile)
    model.load_state_dict(ckpt["model"])
    model.eval()
    return model, profile
