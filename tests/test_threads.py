"""The torch thread count the commands take by default (corn_drake/nn/threads.py)."""

import argparse

import pytest
import torch

from corn_drake.arguments.torch_threads import torch_threads_arg
from corn_drake.nn.threads import auto_torch_threads, torch_threads


@pytest.mark.parametrize("cpus, expected", [(1, 1), (2, 1), (3, None), (16, None)])
def test_auto_is_one_thread_on_small_machines_only(cpus, expected):
    assert auto_torch_threads(cpus) == expected


def test_argument_takes_torch_auto_or_a_count():
    assert torch_threads_arg("torch") is None
    assert torch_threads_arg("auto") == auto_torch_threads()
    assert torch_threads_arg("3") == 3
    for bad in ("0", "-1", "1.5", "two", ""):
        with pytest.raises(argparse.ArgumentTypeError, match="'torch', 'auto' or an integer"):
            torch_threads_arg(bad)


def test_count_is_set_inside_and_given_back_after():
    before = torch.get_num_threads()
    with torch_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before
    with torch_threads(None):  # torch's own: unchanged
        assert torch.get_num_threads() == before


def test_every_command_takes_auto_by_default():
    from corn_drake.cli import build_parser

    parser = build_parser()
    train = parser.parse_args(["train", "--out", "somewhere"])
    bench = parser.parse_args(["bench", "policies", "--report", "r.json"])
    evaluate = parser.parse_args(["evaluate", "--run", "scripted", "--report", "r.json"])
    assert train.torch_threads == bench.torch_threads == evaluate.torch_threads
    assert evaluate.torch_threads == auto_torch_threads()
