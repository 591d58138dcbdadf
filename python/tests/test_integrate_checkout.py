"""cpp-examples/common/checkout_mirror.py, the integration scripts' first step: a git directory
without a work tree (what `fetch` brings), missing some blobs, is laid out anyway, the missing
files named; `git archive` stops at the first missing blob."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "cpp-examples" / "common" / "checkout_mirror.py"

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def run_git(*args: str, cwd: Path) -> str:
    env = dict(
        os.environ,
        GIT_AUTHOR_NAME="t",
        GIT_AUTHOR_EMAIL="t@example.org",
        GIT_COMMITTER_NAME="t",
        GIT_COMMITTER_EMAIL="t@example.org",
    )
    proc = subprocess.run(["git", *args], cwd=cwd, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip()


@pytest.fixture
def mirror(tmp_path: Path) -> Path:
    """A bare git directory of one commit: a source file, an executable script, a symbolic
    link and a data file whose blob was dropped (as the snapshots drop vocabularies)."""
    work = tmp_path / "work"
    (work / "src").mkdir(parents=True)
    (work / "src" / "main.cc").write_text("int main() { return 0; }\n")
    (work / "build.sh").write_text("#!/bin/sh\necho build\n")
    (work / "build.sh").chmod(0o755)
    (work / "Vocabulary").mkdir()
    (work / "Vocabulary" / "ORBvoc.txt.tar.gz").write_bytes(b"\x1f\x8b large data")
    os.symlink("src/main.cc", work / "main-link.cc")
    run_git("init", "-q", cwd=work)
    run_git("add", "-A", cwd=work)
    run_git("commit", "-q", "-m", "v1", cwd=work)
    run_git("tag", "v1.0", cwd=work)
    bare = tmp_path / "mirror.git"
    run_git("clone", "-q", "--bare", str(work), str(bare), cwd=tmp_path)
    data = run_git("rev-parse", "HEAD:Vocabulary/ORBvoc.txt.tar.gz", cwd=work)
    # Unpacked so that one object can be dropped.
    for pack in (bare / "objects" / "pack").glob("*.pack"):
        subprocess.run(["git", "unpack-objects", "-q"], cwd=bare, stdin=pack.open("rb"), check=True)
        pack.unlink()
        pack.with_suffix(".idx").unlink()
    (bare / "objects" / data[:2] / data[2:]).unlink()
    return bare


def lay_out(git_dir: Path, rev: str, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), str(git_dir), rev, str(out)], capture_output=True, text=True
    )


def test_git_archive_stops_at_the_missing_blob(mirror: Path, tmp_path: Path):
    proc = subprocess.run(
        ["git", f"--git-dir={mirror}", "archive", "HEAD"], capture_output=True, cwd=tmp_path
    )
    assert proc.returncode != 0


def test_a_snapshot_missing_blobs_is_laid_out_and_the_missing_named(mirror: Path, tmp_path: Path):
    out = tmp_path / "tree"
    proc = lay_out(mirror, "v1.0", out)
    assert proc.returncode == 0, proc.stderr
    assert "1 blobs missing" in proc.stderr and "ORBvoc.txt.tar.gz" in proc.stderr
    assert (out / "src" / "main.cc").read_text() == "int main() { return 0; }\n"
    assert os.access(out / "build.sh", os.X_OK)
    assert not os.access(out / "src" / "main.cc", os.X_OK)
    assert (out / "main-link.cc").is_symlink()
    assert os.readlink(out / "main-link.cc") == "src/main.cc"
    assert not (out / "Vocabulary" / "ORBvoc.txt.tar.gz").exists()
    assert (out / ".checkout-missing").read_text() == "Vocabulary/ORBvoc.txt.tar.gz\n"
    commit = subprocess.run(
        ["git", f"--git-dir={mirror}", "rev-parse", "v1.0^{commit}"], capture_output=True, text=True
    ).stdout.strip()
    assert (out / ".checkout-commit").read_text() == commit + "\n"


def test_a_rerun_rewrites_nothing(mirror: Path, tmp_path: Path):
    out = tmp_path / "tree"
    assert lay_out(mirror, "HEAD", out).returncode == 0
    source = out / "src" / "main.cc"
    os.utime(source, (1_000_000, 1_000_000))
    assert lay_out(mirror, "HEAD", out).returncode == 0
    assert source.stat().st_mtime == 1_000_000  # a build after it rebuilds nothing


def test_an_unknown_revision_is_refused(mirror: Path, tmp_path: Path):
    proc = lay_out(mirror, "v9.9", tmp_path / "tree")
    assert proc.returncode == 1 and "'v9.9' is not a commit" in proc.stderr
    assert not (tmp_path / "tree").exists()
