"""The staged trainer: runs a profile's stages with checkpoints, resume, curves and DDP."""

from __future__ import annotations

import json
import time
from pathlib import Path

import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader, DistributedSampler, Sampler
from tqdm import tqdm

from dear_train.data.dataset import DearDataset, split_items
from dear_train.evaluation import evaluate
from dear_train.losses import (
    FUSION_WEIGHTS,
    GRADIENT_WEIGHT,
    HARM_WEIGHT,
    depth_l2_loss,
    depth_loss,
    flownet_weights,
    guarded_losses,
    harm,
    multiscale_flow_loss,
)
from dear_train.models.dear import DEAR
from dear_train.models.kpn import uses_classical
from dear_train.training import distributed
from dear_train.training.checkpoint import (
    build_model,
    final_state,
    load_resumable,
    save_atomic,
    training_state,
    warm_start_record,
    warm_start_refine,
)
from dear_train.training.config import Profile, Stage
from dear_train.training.curves import plot_history


def stage_modules(model: DEAR, stage: str) -> list[nn.Module]:
    """The nets a stage trains."""
    parts = {
        "flow": [model.flow],
        "fusion": [model.flow, model.fusion],
        "refine": [model.refine],
        "finetune": [model.flow, model.fusion, model.refine],
    }[stage]
    return [m for m in parts if m is not None]


class StageLoss(nn.Module):
    """``forward(batch)`` → (total loss, named parts) for one stage.

    A module (not a function) so that ``DistributedDataParallel`` can wrap it: DDP hooks
    ``forward``, and ``find_unused_parameters`` covers the nets a stage leaves alone.
    """

    def __init__(
        self, model: DEAR, stage: str, variant: str, harm_weight: float = HARM_WEIGHT
    ) -> None:
        super().__init__()
        self.model = model
        self.stage = stage
        self.variant = variant
        self.harm_weight = harm_weight

    def _depth(self, pred: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        if self.variant == "deeptof":
            return depth_l2_loss(pred, gt, valid)
        lam = 0.0 if self.variant == "nograd" else GRADIENT_WEIGHT
        return depth_loss(pred, gt, valid, lam)

    def forward(self, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
        m = self.model
        rgb, amp, tof = b["rgb"], b["amplitude"], b["tof_depth"]
        gt_flow, valid, gt = b["flow"], b["flow_valid"], b["gt_depth"]
        depth_valid = valid & (gt > 0)
        parts: dict[str, torch.Tensor] = {}
        if self.stage == "refine":
            r = m.refine_depth(rgb, amp, tof, gt_flow, b.get("tof_classical"))
            # Only pixels with a warped measurement: the refiner filters depth, it does not
            # invent it where none maps (the daemon publishes 0 there). Counting holes taught
            # the gated refiner to lower all depth by its largest bias, shrinking the step at
            # every hole edge that the gradient term saw.
            measured = depth_valid & r["depth_warped_valid"]
            if self.variant == "guarded":
                parts.update(
                    guarded_losses(r, gt, depth_valid, measured, self._depth, self.harm_weight)
                )
            else:
                parts["depth"] = self._depth(r["depth"], gt, measured)
                if self.variant == "hybrid" and self.harm_weight > 0:
                    parts["harm"] = self.harm_weight * harm(
                        r["depth"], r["depth_warped"], gt, measured
                    )
        else:
            assert m.flow is not None
            if self.stage == "flow":
                flows = m.flow(rgb, amp)
                parts["rough"] = multiscale_flow_loss(
                    flows, gt_flow, valid, flownet_weights(len(flows))
                )
            else:
                out = (
                    m.forward(rgb, amp, tof, b.get("tof_classical"))
                    if self.stage == "finetune"
                    else m.align(rgb, amp, tof)
                )
                flows = out["flows_rough"]
                assert isinstance(flows, list)
                parts["rough"] = multiscale_flow_loss(
                    flows, gt_flow, valid, flownet_weights(len(flows))
                )
                refn = out["flows_refn"]
                assert isinstance(refn, list)
                parts["refn"] = multiscale_flow_loss(refn, gt_flow, valid, FUSION_WEIGHTS)
                if self.stage == "finetune":
                    d = out["depth"]
                    assert isinstance(d, torch.Tensor)
                    parts["depth"] = self._depth(d, gt, depth_valid)
        total = sum(parts.values(), torch.zeros((), device=rgb.device))
        return total, {k: float(v.detach()) for k, v in parts.items()}


def split_datasets(
    profile: Profile, data: list[Path], classical: bool | None = None
) -> tuple[DearDataset, DearDataset, int]:
    """(training set, validation set, frames skipped) of a profile's data.

    Validation uses fixed misalignments (seed/epoch constant) and crops of the training size.
    ``classical``: load the classical refiner's planes (default: when the profile's variant
    takes them).
    """
    if classical is None:
        classical = uses_classical(profile.variant)
    full = DearDataset(
        data, profile.crop, profile.augment, profile.norm, profile.seed, classical=classical
    )
    train_items, val_items = split_items(full, profile.val_fraction, profile.seed)
    train = DearDataset(
        data, profile.crop, profile.augment, profile.norm, profile.seed, train_items, classical
    )
    val = DearDataset(
        data, profile.crop, profile.augment, profile.norm, profile.seed + 1, val_items, classical
    )
    return train, val, full.skipped


def data_loader(
    dataset: DearDataset, profile: Profile, shuffle: bool, sampler: Sampler | None = None
) -> DataLoader:
    """Batches of ``dataset`` for a profile: shuffled and without a ragged last batch for
    training, in order and complete for validation (``sampler`` replaces the shuffle)."""
    return DataLoader(
        dataset,
        batch_size=profile.batch_size,
        shuffle=shuffle and sampler is None,
        sampler=sampler,
        num_workers=profile.num_workers,
        drop_last=shuffle and len(dataset) >= profile.batch_size,
        persistent_workers=False,
    )


def trains_alignment(profile: Profile) -> bool:
    """Whether any stage of the profile trains the flow or fusion net (else validation skips
    them: a refine-only run would spend most of its validation on untrained flow nets)."""
    return any(s.name != "refine" for s in profile.stages)


class Trainer:
    """Trains a :class:`Profile` on capture directories into ``out_dir``.

    Output: ``checkpoints/last.pt`` (resume), ``checkpoints/stage-NAME.pt`` (end of each stage),
    ``final.pt``, ``history.json``, ``curves.png``.
    """

    def __init__(
        self,
        profile: Profile,
        data: list[Path],
        out_dir: Path,
        device: str | None = None,
        resume: bool = False,
        init_refine: Path | None = None,
    ) -> None:
        self.profile = profile
        self.data = [Path(d) for d in data]
        self.out = Path(out_dir)
        self.dist = distributed.init_from_env()
        self.device = distributed.device_for(self.dist, device)
        torch.manual_seed(profile.seed + self.dist.rank)
        self.train_set, self.val_set, self.skipped = split_datasets(profile, self.data)
        self.model = build_model(profile).to(self.device)
        self.history: list[dict] = []
        self.position = (0, 0)  # (stage index, next epoch)
        self.resume_state: dict | None = None
        #: The bundle a warm-started run began from (``warm_start_record``), kept in every
        #: checkpoint so that a resumed run and its export still name it.
        self.warm_start: dict | None = None
        last = self.out / "checkpoints" / "last.pt"
        if resume and last.exists():
            ckpt = load_resumable(last, profile)
            self.model.load_state_dict(ckpt["model"])
            self.history = ckpt["history"]
            self.position = (ckpt["stage_index"], ckpt["next_epoch"])
            self.resume_state = ckpt
            self.warm_start = ckpt.get("warm_start")
        elif init_refine is not None:
            copied = warm_start_refine(self.model, init_refine)
            self.warm_start = warm_start_record(init_refine)
            if self.dist.is_main:
                self.out.mkdir(parents=True, exist_ok=True)
                (self.out / "init_refine.json").write_text(
                    json.dumps({"bundle": str(init_refine), "parameters": copied}, indent=2)
                )

    def _loader(self, dataset: DearDataset, shuffle: bool) -> DataLoader:
        sampler = (
            DistributedSampler(dataset, shuffle=shuffle, seed=self.profile.seed)
            if self.dist.enabled
            else None
        )
        return data_loader(dataset, self.profile, shuffle, sampler)

    def _provenance(self) -> dict:
        return {} if self.warm_start is None else {"warm_start": self.warm_start}

    def _save(self, path: Path, stage_index: int, next_epoch: int, opt: dict, sched: dict) -> None:
        if not self.dist.is_main:
            return
        save_atomic(
            training_state(
                self.profile,
                self.data,
                self.model,
                stage_index,
                next_epoch,
                opt,
                sched,
                self.history,
                **self._provenance(),
            ),
            path,
        )

    def _budget_spent(self, stage: Stage, stage_start: float) -> bool:
        """Whether the stage's wall-time budget is spent; every rank takes rank 0's answer, so
        that all of them leave the epoch at the same step."""
        if stage.max_seconds is None:
            return False
        spent = time.time() - stage_start >= stage.max_seconds
        if self.dist.enabled:
            spent = distributed.broadcast_flag(spent, self.dist, self.device)
        return spent

    def run(self) -> dict[str, float]:
        """Run (or resume) the schedule; returns the final validation metrics."""
        p = self.profile
        main = self.dist.is_main
        start_stage, start_epoch = self.position
        for si in range(start_stage, len(p.stages)):
            stage = p.stages[si]
            modules = stage_modules(self.model, stage.name)
            for mod in (self.model.flow, self.model.fusion, self.model.refine):
                if mod is not None:
                    mod.requires_grad_(any(mod is x for x in modules))
            params = [q for mod in modules for q in mod.parameters()]
            opt = torch.optim.Adam(params, lr=stage.lr)
            sched = torch.optim.lr_scheduler.StepLR(opt, p.lr_decay_every, p.lr_decay)
            first_epoch = start_epoch if si == start_stage else 0
            if self.resume_state is not None and si == start_stage and first_epoch > 0:
                opt.load_state_dict(self.resume_state["optimizer"])
                sched.load_state_dict(self.resume_state["scheduler"])
            loss_mod: nn.Module = StageLoss(
                self.model, stage.name, p.variant, p.refine_harm_weight()
            )
            if self.dist.enabled:
                loss_mod = DistributedDataParallel(loss_mod, find_unused_parameters=True)
            loader = self._loader(self.train_set, shuffle=True)
            stage_start = time.time()
            out_of_time = False
            for epoch in range(first_epoch, stage.epochs):
                self.train_set.set_epoch(epoch + 1000 * si)
                if isinstance(loader.sampler, DistributedSampler):
                    loader.sampler.set_epoch(epoch + 1000 * si)
                self.model.train()
                total, steps, t0 = 0.0, 0, time.time()
                cut = False  # this epoch ended early by the budget
                limit = p.max_steps_per_epoch or len(loader)
                bar = tqdm(
                    loader,
                    total=min(limit, len(loader)),
                    desc=f"{stage.name} {epoch + 1}/{stage.epochs}",
                    disable=not main,
                    leave=False,
                )
                for batch in bar:
                    if steps >= limit:
                        break
                    out_of_time = self._budget_spent(stage, stage_start)
                    if out_of_time and steps > 0:
                        cut = True
                        break
                    b = {k: v.to(self.device, non_blocking=True) for k, v in batch.items()}
                    loss, parts = loss_mod(b)
                    opt.zero_grad(set_to_none=True)
                    loss.backward()
                    opt.step()
                    total += float(loss.detach())
                    steps += 1
                    bar.set_postfix(
                        loss=f"{float(loss.detach()):.4g}",
                        **{k: f"{v:.3g}" for k, v in parts.items()},
                    )
                # Spent during the epoch's last step: end the stage here, not after one more
                # step and validation in an epoch of its own.
                out_of_time = out_of_time or self._budget_spent(stage, stage_start)
                sched.step()
                train_loss = distributed.mean_across_ranks(
                    total / max(steps, 1), self.dist, self.device
                )
                val = {}
                if main:
                    val = evaluate(
                        self.model,
                        self._loader(self.val_set, shuffle=False),
                        self.device,
                        p.max_val_batches,
                        align=trains_alignment(p),
                    )
                entry = {
                    "stage": stage.name,
                    "epoch": epoch,
                    "steps": steps,
                    "seconds": round(time.time() - t0, 2),
                    "lr": opt.param_groups[0]["lr"],
                    "train_loss": train_loss,
                    "val": val,
                }
                if cut or (out_of_time and epoch + 1 < stage.epochs):
                    entry["stopped"] = "time budget"
                self.history.append(entry)
                stage_done = out_of_time or epoch + 1 == stage.epochs
                if main:
                    tqdm.write(json.dumps(entry))
                    self._save(
                        self.out / "checkpoints" / "last.pt",
                        si + 1 if stage_done else si,
                        0 if stage_done else epoch + 1,
                        opt.state_dict(),
                        sched.state_dict(),
                    )
                    plot_history(self.history, self.out / "curves.png")
                    (self.out / "history.json").write_text(json.dumps(self.history, indent=1))
                if out_of_time:
                    break
            if main:
                self._save(self.out / "checkpoints" / f"stage-{stage.name}.pt", si + 1, 0, {}, {})
            distributed.barrier(self.dist)
        state = final_state(
            self.profile,
            self.data,
            self.model,
            {"train": len(self.train_set), "val": len(self.val_set), "skipped": self.skipped},
            self.history,
            **self._provenance(),
        )
        if main:
            save_atomic(state, self.out / "final.pt")
        distributed.shutdown(self.dist)
        return state["metrics"]
