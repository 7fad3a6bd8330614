"""Shared fixtures: a small synthetic capture directory and deterministic, small-thread torch."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from dear_train.data.synthetic import write_synthetic_capture


@pytest.fixture(autouse=True)
def _deterministic() -> None:
    torch.manual_seed(0)
    torch.set_num_threads(2)


@pytest.fixture(scope="session")
def capture_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 frames, 96×128: 3 misaligned (with .flo), 3 aligned (for augmentation)."""
    return write_synthetic_capture(tmp_path_factory.mktemp("capture"), frames=6, seed=3)
