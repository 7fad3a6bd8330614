"""End to end: ``dear-train --profile smoke`` on a generated capture, resume, export, evaluate."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dear_train.evaluation import main as evaluate_main
from dear_train.export import main as export_main
from dear_train.training.checkpoint import load
from dear_train.training.cli import main as train_main


def test_smoke_training_resume_and_export(
    capture_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    train_main(["--profile", "smoke", "--data", str(capture_dir), "--out", str(run)])
    for name in ("final.pt", "curves.png", "history.json", "checkpoints/last.pt"):
        assert (run / name).exists(), name
    for stage in ("flow", "fusion", "refine", "finetune"):
        assert (run / "checkpoints" / f"stage-{stage}.pt").exists()
    history = json.loads((run / "history.json").read_text())
    assert [h["stage"] for h in history] == ["flow", "fusion", "refine", "finetune"]
    assert all(h["steps"] == 2 for h in history)
    final = load(run / "final.pt")
    assert "aepe_refined" in final["metrics"] and "mae_pipeline.all" in final["metrics"]

    # Resuming a finished run trains nothing more and keeps the history.
    train_main(["--profile", "smoke", "--data", str(capture_dir), "--out", str(run), "--resume"])
    assert len(json.loads((run / "history.json").read_text())) == 4

    bundle = tmp_path / "bundle"
    export_main(["--checkpoint", str(run / "final.pt"), "--out", str(bundle)])
    manifest = json.loads((bundle / "model.json").read_text())
    assert manifest["training"]["profile"]["name"] == "smoke"
    assert manifest["validation"] == final["metrics"]
    assert manifest["training"]["frames"]["train"] + manifest["training"]["frames"]["val"] == 6

    capsys.readouterr()
    evaluate_main(
        ["--checkpoint", str(run / "final.pt"), "--data", str(capture_dir), "--max-frames", "2"]
    )
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["aepe_rough"] > 0 and "mae_input_misaligned.all" in metrics


def test_resume_continues_where_it_stopped(capture_dir: Path, tmp_path: Path) -> None:
    """A run interrupted after the first stage resumes at the second."""
    import torch

    from dear_train.training.config import get_profile
    from dear_train.training.trainer import Trainer

    run = tmp_path / "run"
    profile = get_profile("smoke")
    short = type(profile)(**{**profile.__dict__, "stages": profile.stages[:1]})
    Trainer(short, [capture_dir], run).run()
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=False)
    assert (last["stage_index"], last["next_epoch"]) == (1, 0)
    # Same position, full profile: the stored profile differs, so resume must refuse.
    try:
        Trainer(profile, [capture_dir], run, resume=True)
    except ValueError as e:
        assert "different profile" in str(e)
    else:
        raise AssertionError("resume with another profile must fail")


def test_a_stage_ends_when_its_time_budget_is_spent(capture_dir: Path, tmp_path: Path) -> None:
    """A spent budget ends the stage after the epoch in progress (one step here, where five
    epochs of two were asked for), which is validated and saved; the next stage runs as usual."""
    import torch

    from dear_train.training.config import Stage, get_profile
    from dear_train.training.trainer import Trainer

    profile = get_profile("smoke")
    budgeted = type(profile)(
        **{
            **profile.__dict__,
            "stages": (Stage("flow", 5, 1e-3, max_seconds=1e-6), Stage("fusion", 1, 1e-3)),
        }
    )
    run = tmp_path / "run"
    Trainer(budgeted, [capture_dir], run).run()
    history = json.loads((run / "history.json").read_text())
    assert [(h["stage"], h["steps"], h.get("stopped")) for h in history] == [
        ("flow", 1, "time budget"),
        ("fusion", 2, None),
    ]
    assert history[0]["val"], "the cut epoch is validated"
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=False)
    assert (last["stage_index"], last["next_epoch"]) == (2, 0)
    with pytest.raises(ValueError, match="max_seconds must be positive"):
        Stage("flow", 1, 1e-3, max_seconds=0)


def test_a_warm_started_run_keeps_its_lineage_through_the_export(
    capture_dir: Path, tmp_path: Path
) -> None:
    """``--init-refine``: the checkpoints and the exported ``model.json`` name the bundle the
    run began from, its refine graph's checksum and that bundle's own recipe, so a refiner
    trained in sittings (bundle → run → bundle → run) keeps its whole history."""
    from dear_train.training.config import Stage, get_profile
    from dear_train.training.trainer import Trainer

    # The refine stage alone: the lineage is the same for any schedule, and it is quick.
    profile = get_profile("smoke", stages=(Stage("refine", 1, 1e-3),))

    def train_and_export(name: str, init: Path | None) -> dict:
        run = tmp_path / f"run-{name}"
        Trainer(profile, [capture_dir], run, init_refine=init).run()
        bundle = tmp_path / f"bundle-{name}"
        export_main(["--checkpoint", str(run / "final.pt"), "--out", str(bundle), "--no-check"])
        return json.loads((bundle / "model.json").read_text())

    first = train_and_export("first", None)
    assert "warm_start" not in first["training"]
    second = train_and_export("second", tmp_path / "bundle-first")
    start = second["training"]["warm_start"]
    assert start["bundle"] == str(tmp_path / "bundle-first")
    assert start["refine_sha256"] == first["graphs"]["refine"]["sha256"]
    assert start["training"]["epochs_trained"] == first["training"]["epochs_trained"]
    assert load(tmp_path / "run-second" / "checkpoints" / "last.pt")["warm_start"] == start
    third = train_and_export("third", tmp_path / "bundle-second")
    lineage = third["training"]["warm_start"]["training"]["warm_start"]
    assert lineage["bundle"] == str(tmp_path / "bundle-first")
