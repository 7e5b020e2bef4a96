"""Every malformed input ends in one ``cloth-usd: error:`` line, exit code 2, and no file.

The corpus comes from ``make_corpus.py`` (issue #6). Each case runs in-process through
``cloth_usd.cli.main`` with file-descriptor capture, so anything USD's C++ side prints
to stderr counts against the one-line rule too; a few run as real subprocesses.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from cloth_usd.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_corpus import SHARED, Case, build_corpus  # noqa: E402

PREFIX = "cloth-usd: error: "
#: Folders other cases read from; their bytes must never change.
COMMON = (SHARED, "body_models")


def _listing() -> list[Case]:
    """The case list, for parametrizing at collection (the files are built again below)."""
    with tempfile.TemporaryDirectory() as tmp:
        return build_corpus(tmp)


CASES = _listing()


def _param(case: Case):
    marks = [pytest.mark.xfail(strict=True, reason=case.known_bug)] if case.known_bug else []
    return pytest.param(case.name, marks=marks, id=case.name)


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> tuple[Path, dict[str, Case]]:
    root = tmp_path_factory.mktemp("corpus")
    cases = build_corpus(root)
    return root, {c.name: c for c in cases}


def _tree(root: Path) -> set[str]:
    """Every file and folder under root, hidden ones included."""
    found = set()
    for folder, dirs, files in os.walk(root):
        for name in dirs + files:
            found.add(os.path.relpath(os.path.join(folder, name), root))
    return found


def _digests(root: Path, folders) -> dict[str, str]:
    out = {}
    for sub in folders:
        for folder, _, files in os.walk(root / sub):
            for name in files:
                path = Path(folder) / name
                if path.is_symlink():  # may dangle or loop (the symlink cases): its target is its content
                    out[os.path.relpath(path, root)] = "-> " + os.readlink(path)
                    continue
                out[os.path.relpath(path, root)] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def _check_error(err: str, case: Case) -> None:
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1, f"expected one stderr line, got {len(lines)}:\n{err}"
    assert lines[0].startswith(PREFIX), lines[0]
    for part in case.expect:
        assert part in lines[0], f"{part!r} not in {lines[0]!r}"


def test_corpus_is_large_enough(corpus):
    root, cases = corpus
    assert len(cases) >= 50
    assert [c.name for c in CASES] == list(cases)
    assert all((root / name).is_dir() for name in cases)


@pytest.mark.parametrize("name", [_param(c) for c in CASES])
def test_case_fails_cleanly(corpus, name, capfd, monkeypatch):
    root, cases = corpus
    case = cases[name]
    monkeypatch.chdir(root)
    watched = (name, *COMMON)
    tree, digests = _tree(root), _digests(root, watched)
    capfd.readouterr()
    code = main(case.argv)
    out, err = capfd.readouterr()
    assert code == 2, (code, out, err)
    _check_error(err, case)
    assert _tree(root) == tree, f"files appeared or vanished: {_tree(root) ^ tree}"
    assert _digests(root, watched) == digests
    for path in case.must_not_exist:
        assert not (root / path).exists(), f"{path} was created: pickle code ran"


SUBPROCESS_CASES = ["garbage_usda", "missing_joint_left_elbow", "body_pickle_os_system", "frames_words",
                    "sublayer_missing", "bundle_onnx_truncated"]


@pytest.mark.parametrize("name", SUBPROCESS_CASES)
def test_case_in_a_subprocess(corpus, name):
    root, cases = corpus
    case = cases[name]
    tree = _tree(root)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[2]), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "cloth_usd.cli", *case.argv], cwd=root, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc
    _check_error(proc.stderr, case)
    assert proc.stdout == ""
    assert _tree(root) == tree
    for path in case.must_not_exist:
        assert not (root / path).exists()
