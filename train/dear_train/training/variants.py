"""Refinement variants trained side by side: one data stream, one optimiser per variant.

The paper's ablation tables (DEAR Tables 2/3) compare refinement nets trained with the same
recipe. On the 2-core CPU machine the recipe's cost is the data pipeline, not the nets (a
training step of an edge refiner takes ~0.1 s; loading and augmenting its batch ~0.25 s), so
training the variants one after another would decode every batch once per variant. Here every
variant sees the *identical* batches in the identical order — a tighter control than separate
runs — and the batch is decoded once.

Each variant's result is a normal run directory (``OUT/VARIANT/final.pt``, ``history.json``
and ``checkpoints/last.pt`` after every epoch) that ``dear-export --refine-only`` and
``dear-evaluate`` read like any other; ``resume=True`` continues all variants from their
``last.pt`` (they must stand at the same epoch). Only refine-only profiles qualify (the
variants differ in the refinement net alone).
"""

from __future__ import annotations

import itertools
import json
import time
from dataclasses import replace
from pathlib import Path

import torch
from tqdm import tqdm

from dear_train.evaluation import evaluate
from dear_train.models.dear import DEAR
from dear_train.models.kpn import uses_classical
from dear_train.training import distributed
from dear_train.training.checkpoint import (
    build_model,
    final_state,
    load_resumable,
    save_atomic,
    training_state,
)
from dear_train.training.config import Profile
from dear_train.training.trainer import StageLoss, data_loader, split_datasets


def train_side_by_side(
    profile: Profile,
    variants: list[str],
    data: list[Path],
    out_dir: Path,
    device: str | None = None,
    resume: bool = False,
) -> dict[str, dict[str, float]]:
    """Train ``variants`` of the profile's refinement net on identical batches.

    Returns each variant's final validation metrics (refinement at the true flow).
    """
    if not variants or len(set(variants)) != len(variants):
        raise ValueError(f"give distinct variants to train side by side, got {variants}")
    if any(s.name != "refine" for s in profile.stages):
        raise ValueError(
            f"profile {profile.name!r} trains {[s.name for s in profile.stages]}; "
            "side-by-side training needs a refine-only profile (e.g. cpu-gated)"
        )
    dev = distributed.device_for(distributed.DistInfo(), device)
    data = [Path(d) for d in data]
    out_dir = Path(out_dir)
    torch.manual_seed(profile.seed)
    train_set, val_set, skipped = split_datasets(
        profile, data, classical=any(uses_classical(v) for v in variants)
    )
    profiles = {v: replace(profile, variant=v) for v in variants}
    models: dict[str, DEAR] = {}
    for v in variants:
        # Same initial weights as a separate `dear-train --variant v` run of this profile.
        torch.manual_seed(profile.seed)
        models[v] = build_model(profiles[v]).to(dev)
        assert models[v].refine is not None
        for part in (models[v].flow, models[v].fusion):
            if part is not None:
                part.requires_grad_(False)
    losses = {
        v: StageLoss(models[v], "refine", v, profiles[v].refine_harm_weight()) for v in variants
    }
    history: dict[str, list[dict]] = {v: [] for v in variants}
    position = (0, 0)  # (stage index, next epoch), shared by every variant
    saved: dict[str, dict] = {}
    if resume:
        for v in variants:
            ckpt = load_resumable(out_dir / v / "checkpoints" / "last.pt", profiles[v])
            models[v].load_state_dict(ckpt["model"])
            history[v] = ckpt["history"]
            saved[v] = ckpt
        positions = {(c["stage_index"], c["next_epoch"]) for c in saved.values()}
        if len(positions) != 1:
            raise ValueError(f"{out_dir}: the variants' checkpoints stand at different epochs")
        position = positions.pop()

    train_loader = data_loader(train_set, profile, shuffle=True)
    # The validation batches are fixed (constant seed, no epoch): decode them once for every
    # variant and epoch.
    val_batches = list(
        itertools.islice(data_loader(val_set, profile, shuffle=False), profile.max_val_batches)
    )
    for si, stage in enumerate(profile.stages):
        if si < position[0]:
            continue
        first_epoch = position[1] if si == position[0] else 0
        opts = {
            v: torch.optim.Adam(models[v].refine.parameters(), lr=stage.lr)  # type: ignore[union-attr]
            for v in variants
        }
        scheds = {
            v: torch.optim.lr_scheduler.StepLR(opts[v], profile.lr_decay_every, profile.lr_decay)
            for v in variants
        }
        if saved and first_epoch > 0:
            for v in variants:
                opts[v].load_state_dict(saved[v]["optimizer"])
                scheds[v].load_state_dict(saved[v]["scheduler"])
        for epoch in range(first_epoch, stage.epochs):
            train_set.set_epoch(epoch + 1000 * si)
            for m in models.values():
                m.train()
            totals = dict.fromkeys(variants, 0.0)
            seconds = dict.fromkeys(variants, 0.0)
            steps, t0 = 0, time.time()
            limit = profile.max_steps_per_epoch or len(train_loader)
            bar = tqdm(
                train_loader,
                total=min(limit, len(train_loader)),
                leave=False,
                desc=f"{stage.name} {epoch + 1}/{stage.epochs} ×{len(variants)}",
            )
            for batch in bar:
                if steps >= limit:
                    break
                b = {k: t.to(dev, non_blocking=True) for k, t in batch.items()}
                for v in variants:
                    ts = time.time()
                    loss, _ = losses[v](b)
                    opts[v].zero_grad(set_to_none=True)
                    loss.backward()
                    opts[v].step()
                    totals[v] += float(loss.detach())
                    seconds[v] += time.time() - ts
                steps += 1
            for v in variants:
                scheds[v].step()
                m = models[v]
                # Validation of the refinement alone, at the true flow.
                val = evaluate(
                    DEAR(None, None, m.refine, m.max_depth), val_batches, dev, align=False
                )
                entry = {
                    "stage": stage.name,
                    "epoch": epoch,
                    "steps": steps,
                    "seconds": round(time.time() - t0, 2),
                    "net_seconds": round(seconds[v], 2),
                    "lr": opts[v].param_groups[0]["lr"],
                    "train_loss": totals[v] / max(steps, 1),
                    "val": val,
                }
                history[v].append(entry)
                tqdm.write(json.dumps({"variant": v, **entry}))
                run = out_dir / v
                run.mkdir(parents=True, exist_ok=True)
                (run / "history.json").write_text(json.dumps(history[v], indent=1))
                done = epoch + 1 == stage.epochs
                save_atomic(
                    training_state(
                        profiles[v],
                        data,
                        m,
                        si + 1 if done else si,
                        0 if done else epoch + 1,
                        opts[v].state_dict(),
                        scheds[v].state_dict(),
                        history[v],
                    ),
                    run / "checkpoints" / "last.pt",
                )
    frames = {"train": len(train_set), "val": len(val_set), "skipped": skipped}
    finals = {}
    for v in variants:
        state = final_state(
            profiles[v], data, models[v], frames, history[v], trained_with=sorted(variants)
        )
        save_atomic(state, out_dir / v / "final.pt")
        finals[v] = state["metrics"]
    return finals
