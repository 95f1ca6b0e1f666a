"""A student built on the contact-pretrained encoder (encoder.pt), and what of it is trained.

The student's patch tokeniser (tokenizer MLP + position embedding), hand token and transformer
are the pretrained encoder's, with the input normalisation it was pretrained with; its task
tokens, queries, cross-attention, GRU and actor start fresh. By default DAgger trains all of it:
the transformer meets new tokens (goal, joints, previous action) and partial clouds it was not
pretrained on, so it has to adapt; `frozen` keeps named groups (e.g. "patch_tokenizer") at their
pretrained values instead.

The pretraining-quality bar (rl/pretrained_encoders.check_pretrained on student.encoder, which keeps the
pretraining record; contact F1 >= 0.8) is the caller's: nn/ does not import rl/, and the
distillation command holds the --allow-weak-encoder flag.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.nn.encoders.encoder_files import load_frozen_encoder
from corn_drake.nn.student import PARAMETER_GROUPS, StudentPolicy


def student_from_encoder(path: str | Path, frozen: tuple[str, ...] | list[str] = (),
                         **student_kwargs) -> StudentPolicy:
    """A StudentPolicy whose encoder (weights + input normalisation) is the CORN encoder saved at
    `path`; every parameter group is trained except those in `frozen`. A missing or corrupt file,
    an encoder of another kind, or an unknown group name is an InputError naming it."""
    unknown = sorted(set(frozen) - set(PARAMETER_GROUPS))
    if unknown:
        raise InputError(f"unknown student parameter groups {unknown} to freeze; "
                         f"expected some of {PARAMETER_GROUPS}")
    encoder = load_frozen_encoder(path)  # InputError naming `path` when it is no encoder
    if encoder.kind != "corn":
        raise InputError(f"the student needs a corn (patch transformer) encoder, {path} holds a "
                         f"{encoder.kind} one")
    student = StudentPolicy(encoder, **student_kwargs)
    # load_frozen_encoder returns the encoder in eval mode with gradients off (the teacher's
    # use); the student trains it, so both are undone here.
    student.train()
    student.set_frozen(frozen)
    return student
