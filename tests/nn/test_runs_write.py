"""A run folder's files on a full disk: one OutputWriteError naming the file, nothing left behind."""

from __future__ import annotations

import builtins
import errno
import os

import pytest

torch = pytest.importorskip("torch", reason="run folders hold torch checkpoints")

from cloth_usd.errors import OutputWriteError  # noqa: E402
from cloth_usd.nn import runs  # noqa: E402


class _FullDisk:
    """A file whose writes fail as on a full device."""

    def __init__(self, path, mode="r", *args, **kwargs):
        self._f = builtins.open(path, mode, *args, **kwargs)

    def write(self, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


@pytest.mark.parametrize("write", [lambda p: runs.atomic_save({"w": torch.zeros(3)}, p),
                                   lambda p: runs.atomic_text("{}\n", p)], ids=["atomic_save", "atomic_text"])
@pytest.mark.parametrize("at", ["write", "rename"])
def test_a_full_disk_is_an_output_write_error_and_leaves_the_file_as_it_was(tmp_path, monkeypatch, write, at):
    target = tmp_path / "best.pt"
    target.write_bytes(b"the last good one")
    if at == "write":
        monkeypatch.setattr(runs, "open", _FullDisk, raising=False)
    else:
        def replace(src, dst):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        monkeypatch.setattr(runs.os, "replace", replace)
    with pytest.raises(OutputWriteError, match=r"best.pt: no space left on device; free some space in"):
        write(target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best.pt"]
    assert target.read_bytes() == b"the last good one"


def test_atomic_save_still_writes_what_torch_load_reads(tmp_path):
    runs.atomic_save({"w": torch.arange(4)}, tmp_path / "c.pt")
    assert torch.equal(torch.load(tmp_path / "c.pt")["w"], torch.arange(4))
    runs.atomic_text("x\n", tmp_path / "r.json")
    assert (tmp_path / "r.json").read_text() == "x\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.pt", "r.json"]
