"""Shared fixtures: a small synthetic capture directory, deterministic, small-thread torch, and a
loader for the generator scripts under fixtures/ (which are not a package)."""

from __future__ import annotations

import importlib.util
import types
from collections.abc import Callable
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


@pytest.fixture(scope="session")
def fixture_maker() -> Callable[[Path], types.ModuleType]:
    """Imports a fixture generator script (e.g. fixtures/metrics/make_metrics.py) by its path."""

    def load(script: Path) -> types.ModuleType:
        spec = importlib.util.spec_from_file_location(script.stem, script)
        assert spec is not None and spec.loader is not None, f"cannot import {script}"
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load
