"""Checkpoints: resumable training state and the final model file.

``last.pt`` (written after every epoch) holds everything needed to resume: the profile, the
position in the schedule, the three nets, the optimiser and scheduler state and the history.
``final.pt`` holds the trained nets, the profile and the validation metrics; ``dear-export``
and ``dear-evaluate`` read it.
"""

from __future__ import annotations

import json
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
        build_refine(profile.tier, profile.variant, profile.refine_context, profile.refine_widths),
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
    **extra: object,
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
        **extra,
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


def warm_start_record(bundle: Path) -> dict:
    """What a warm-started run records of its start (``warm_start`` in its checkpoints, then in
    the exported ``model.json``): the bundle, its refine graph's SHA-256 and that bundle's own
    refine recipe, which names *its* start in turn, so a refiner trained in several sittings
    keeps its whole lineage. A bundle without a readable manifest records only its path."""
    record: dict = {"bundle": str(bundle)}
    try:
        manifest = json.loads((Path(bundle) / "model.json").read_text())
    except (OSError, ValueError):
        return record
    refine = manifest.get("graphs", {}).get("refine", {})
    record["refine_sha256"] = refine.get("sha256")
    training = manifest.get("training", {})
    record["training"] = training.get("refine", training)
    return record


def warm_start_refine(model: DEAR, bundle: Path) -> list[str]:
    """Copy the refinement weights of a format-2 bundle's ``refine.onnx`` into ``model.refine``.

    The exported graph keeps the parameters under their module names (``net.backbone.…``), so a
    refiner whose head grew (``hybrid`` → ``guarded``: 13 → 16 maps) starts from the shipped
    backbone and head; the head's extra channels keep their initialisation. Returns the names
    copied. Raises ``ValueError`` when the file has none of the model's parameters or a shape
    disagrees beyond a grown head.
    """
    import onnx
    from onnx import numpy_helper

    if model.refine is None:
        raise ValueError("warm start: the model has no refinement net")
    path = Path(bundle) / "refine.onnx"
    if not path.is_file():
        raise ValueError(f"warm start: {path} does not exist")
    graph = onnx.load(str(path)).graph
    weights = {
        init.name.removeprefix("net."): torch.from_numpy(numpy_helper.to_array(init).copy())
        for init in graph.initializer
        if init.name.startswith("net.")
    }
    # state_dict() shares storage with the parameters: copying into it sets them.
    state = model.refine.state_dict()
    copied = []
    with torch.no_grad():
        for name, w in weights.items():
            if name not in state:
                continue
            target = state[name]
            if w.shape == target.shape:
                target.copy_(w)
            elif name.startswith("backbone.head.") and w.shape[1:] == target.shape[1:]:
                if w.shape[0] > target.shape[0]:
                    raise ValueError(f"warm start: {path}: {name} has more maps than the model")
                target[: w.shape[0]].copy_(w)
            else:
                raise ValueError(
                    f"warm start: {path}: {name} is {tuple(w.shape)}, the model's "
                    f"{tuple(target.shape)}"
                )
            copied.append(name)
    if not copied:
        raise ValueError(f"warm start: {path} holds none of the refinement net's parameters")
    return copied
