"""The one exception type for a user's bad input: a wrong argument, a missing or corrupt file.

`corn-drake` prints such an error as one line naming the argument or file and exits non-zero,
with no traceback (`--debug` or CORN_DRAKE_DEBUG=1 shows it). Anything else that escapes a
command is a bug and keeps its traceback. It subclasses ValueError so library callers that
already catch ValueError for bad configs keep working.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input from the user; the message must name the argument, field or file."""


class MissingInputError(InputError, FileNotFoundError):
    """A file or folder the user named does not exist. Also a FileNotFoundError, so callers that
    catch that for a missing file keep working."""


class DiskFullError(InputError, OSError):
    """A write failed for want of space (ENOSPC, or EDQUOT: a quota): not a bug, and nothing
    the program can do about it, so one line saying what was kept and what to free. Also an
    OSError, so callers that catch that for a failed write keep working."""


def is_disk_full(error: BaseException) -> bool:
    """Whether `error` is a write that failed because the disk, or the user's quota on it, is
    full (ENOSPC, EDQUOT)."""
    import errno

    return isinstance(error, OSError) and error.errno in {errno.ENOSPC,
                                                          getattr(errno, "EDQUOT", errno.ENOSPC)}


def load_error_detail(error: Exception) -> str:
    """The last line of a load_state_dict error (the mismatch itself, without torch's preamble),
    or the error's type when it has no message: what a one-line InputError quotes."""
    text = str(error).strip()
    return text.splitlines()[-1].strip() if text else type(error).__name__


def network_mismatch(path, kind: str, error: RuntimeError) -> InputError:
    """The error for saved weights (`path`) of a `kind` network whose shape has changed since
    they were written (e.g. the PointNet's input channels): names the file and the last line of
    torch's message (a mismatch), not the whole dump."""
    return InputError(f"{path} holds {kind} weights this version's network does not fit "
                      f"({load_error_detail(error)}); pretrain it again into a new folder")
