"""Test set-up: import the package from the source tree; small CPU thread count; shared helpers."""
import os
import sys

import pytest
import torch

sys.path.insert(0, os.path.abspath(os.path.join(os.path.dirname(__file__), "..")))
torch.set_num_threads(min(2, torch.get_num_threads()))

# TENSORHOLO_FIXTURES: compare against fixtures regenerated elsewhere (CI: by the freshly built holo).
FIXTURES = os.environ.get("TENSORHOLO_FIXTURES") or os.path.join(os.path.dirname(__file__), "fixtures")


@pytest.fixture(scope="session")
def fixtures_dir():
    return FIXTURES


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """A synthetic dataset (24×24 frames, 2-layer LDI) in the documented npz format, written once."""
    from tensorholo_training.data import write_synthetic_dataset

    root = tmp_path_factory.mktemp("tiny_dataset")
    return write_synthetic_dataset(str(root), {"train": 8, "val": 4}, 24, 24, layers=2, per_shard=4, seed=3)
