"""The refinement runs torch with a limited number of threads and restores it afterwards."""

import pytest
import torch

from physinfer.errors import UserInputError
from physinfer.threads import refinement_torch_threads, torch_threads


def test_limit_applies_inside_and_restores_after():
    before = torch.get_num_threads()
    with torch_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before


def test_environment_variable_sets_the_count(monkeypatch):
    monkeypatch.delenv("PHYSINFER_TORCH_THREADS", raising=False)
    assert refinement_torch_threads() == 1
    monkeypatch.setenv("PHYSINFER_TORCH_THREADS", "3")
    assert refinement_torch_threads() == 3
    monkeypatch.setenv("PHYSINFER_TORCH_THREADS", "many")
    with pytest.raises(UserInputError, match="PHYSINFER_TORCH_THREADS"):
        refinement_torch_threads()
