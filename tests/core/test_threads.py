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


def test_refine_and_infer_run_their_torch_work_under_the_limit(monkeypatch):
    from physinfer.posterior.infer_workflow import infer
    from physinfer.session import refine
    from physinfer.threads import with_refinement_threads

    assert refine.__wrapped__ and infer.__wrapped__  # both commands are wrapped
    monkeypatch.setenv("PHYSINFER_TORCH_THREADS", "1")
    torch.set_num_threads(2)
    seen = with_refinement_threads(torch.get_num_threads)()
    assert seen == 1 and torch.get_num_threads() == 2
