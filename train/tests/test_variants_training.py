"""Side-by-side training of refinement variants (``dear-train --variants``)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from dear_train.training.checkpoint import build_model, load, load_model
from dear_train.training.cli import main as train_main
from dear_train.training.config import PROFILES, Stage
from dear_train.training.variants import train_side_by_side

#: cpu-gated shrunk to the 96×128 test capture and two short epochs.
TINY = replace(
    PROFILES["cpu-gated"],
    crop=(64, 96),
    stages=(Stage("refine", 2, 1e-3),),
    max_steps_per_epoch=2,
    max_val_batches=1,
    val_fraction=0.25,
    num_workers=0,
)


def refine_weights(path: Path) -> dict[str, torch.Tensor]:
    return {k: v for k, v in load(path)["model"].items() if k.startswith("refine.")}


def test_each_variant_trains_into_its_own_run_on_identical_batches(
    capture_dir: Path, tmp_path: Path
) -> None:
    pair = train_side_by_side(TINY, ["gated", "kpn"], [capture_dir], tmp_path / "pair")
    assert set(pair) == {"gated", "kpn"}
    for v in ("gated", "kpn"):
        run = tmp_path / "pair" / v
        model, profile = load_model(run / "final.pt")
        assert profile.variant == v and model.refine is not None
        history = json.loads((run / "history.json").read_text())
        frames = load(run / "final.pt")["frames"]["train"]
        steps = min(TINY.max_steps_per_epoch, frames // TINY.batch_size)
        assert [h["epoch"] for h in history] == [0, 1]
        assert steps >= 1 and all(h["steps"] == steps for h in history)
        # Refinement-only validation: no flow metrics from nets this run never trained.
        assert "mae_refined_gtflow.all" in history[-1]["val"]
        assert "aepe_rough" not in history[-1]["val"]
        init = build_model(profile).refine.state_dict()  # type: ignore[union-attr]
        trained = refine_weights(run / "final.pt")
        assert any(not torch.equal(trained[f"refine.{k}"], w) for k, w in init.items())

    # Resuming a finished run trains nothing more and keeps the history.
    train_side_by_side(TINY, ["gated", "kpn"], [capture_dir], tmp_path / "pair", resume=True)
    assert len(json.loads((tmp_path / "pair" / "kpn" / "history.json").read_text())) == 2

    # The same variant trained alone gets the same batches in the same order, so the same
    # weights: the comparison between variants is not confounded by what each one saw.
    train_side_by_side(TINY, ["gated"], [capture_dir], tmp_path / "alone")
    alone = refine_weights(tmp_path / "alone" / "gated" / "final.pt")
    together = refine_weights(tmp_path / "pair" / "gated" / "final.pt")
    for k, w in alone.items():
        # (Adam moves a weight by ~lr = 1e-3 per step; float reductions differ by ~1e-8.)
        torch.testing.assert_close(together[k], w, rtol=0, atol=1e-6)


def test_only_refine_only_profiles_and_distinct_variants(capture_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="refine-only profile"):
        train_side_by_side(PROFILES["smoke"], ["kpn", "unet"], [capture_dir], tmp_path)
    with pytest.raises(ValueError, match="distinct variants"):
        train_side_by_side(TINY, ["kpn", "kpn"], [capture_dir], tmp_path)
    with pytest.raises(SystemExit):
        args = ["--profile", "cpu-gated", "--variants", "kpn", "--variant", "unet"]
        train_main([*args, "--data", str(capture_dir), "--out", str(tmp_path)])


def test_an_interrupted_run_resumes_where_it_stopped(capture_dir: Path, tmp_path: Path) -> None:
    one_epoch = replace(TINY, stages=(Stage("refine", 1, 1e-3),))
    # Stop after the first of two epochs: a run with one epoch writes last.pt at "stage 1".
    # Rewrite it as "stage 0, next epoch 1" of the two-epoch profile, what an interrupted
    # two-epoch run leaves.
    train_side_by_side(one_epoch, ["gated", "kpn"], [capture_dir], tmp_path / "run")
    for v in ("gated", "kpn"):
        path = tmp_path / "run" / v / "checkpoints" / "last.pt"
        ckpt = load(path)
        ckpt.update(profile=replace(TINY, variant=v).to_dict(), stage_index=0, next_epoch=1)
        torch.save(ckpt, path)
    train_side_by_side(TINY, ["gated", "kpn"], [capture_dir], tmp_path / "run", resume=True)
    history = json.loads((tmp_path / "run" / "kpn" / "history.json").read_text())
    assert [h["epoch"] for h in history] == [0, 1]
    with pytest.raises(FileNotFoundError, match="unet"):
        train_side_by_side(TINY, ["gated", "unet"], [capture_dir], tmp_path / "run", resume=True)
