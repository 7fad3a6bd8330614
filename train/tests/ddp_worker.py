"""A tiny refine-only training that ``tests/test_distributed.py`` runs under ``torchrun`` (two
Gloo ranks on the CPU) and as one process: each rank writes its final refinement weights and
its per-epoch training losses beside the run, ``rankR.pt`` / ``rankR.json``.

Usage: ``python ddp_worker.py CAPTURE OUT BATCH`` (``torchrun --nproc_per_node=N ddp_worker.py``
for N ranks; BATCH is per rank).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import torch

from dear_train.training.config import Profile, Stage
from dear_train.training.trainer import Trainer


def profile(batch: int) -> Profile:
    """Four training frames (a 5-frame capture, one held out): with ``batch`` 4 on one process
    or 2 on each of two ranks, every step sees the same four samples, so the runs differ only in
    how the loss is averaged and summed."""
    return Profile(
        name="ddp-check",
        tier="edge",
        crop=(48, 64),
        batch_size=batch,
        stages=(Stage("refine", 3, 1e-3),),
        lr_decay_every=1,
        val_fraction=0.2,
        max_val_batches=1,
        num_workers=0,
    )


def main(capture: Path, out: Path, batch: int) -> None:
    torch.set_num_threads(1)
    trainer = Trainer(profile(batch), [capture], out, "cpu")
    trainer.run()
    rank = int(os.environ.get("RANK", "0"))
    assert trainer.model.refine is not None
    torch.save(trainer.model.refine.state_dict(), out / f"rank{rank}.pt")
    losses = [h["train_loss"] for h in trainer.history]
    (out / f"rank{rank}.json").write_text(json.dumps(losses))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]))
