#!/usr/bin/env python3
"""Lays out the tree of one commit of a git directory (a bare clone, or a mirror fetched
without a work tree) into a folder, skipping the blobs the git directory lacks.

    python3 cpp-examples/common/checkout_mirror.py GIT_DIR REV OUT_DIR

``git archive`` and ``git checkout`` stop at the first missing blob; mirrors made for reading
often lack large data files (ORB-SLAM3's snapshot misses its vocabulary tarball and about 100
IMU timestamp files). This lists the commit's tree with ``git ls-tree -r``, writes each blob
with ``git cat-file blob`` (modes kept: executables, symbolic links), and names the missing
ones in ``OUT_DIR/.checkout-missing`` (one path per line) and on stderr. Files already holding
the right content are not rewritten, so a rerun leaves timestamps alone and a build after it
rebuilds nothing. ``OUT_DIR/.checkout-commit`` records the commit laid out.

Exit status: 0 when the tree is laid out (missing blobs only reported), 1 when ``REV`` is not
a commit of ``GIT_DIR`` or ``git`` fails otherwise, 2 for a usage error.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import List, Sequence


class CheckoutError(Exception):
    """``git`` could not read the commit or its tree."""


@dataclass(frozen=True)
class Entry:
    """One blob of a tree: its mode (``100644``, ``100755``, ``120000``), id and path."""

    mode: str
    oid: str
    path: str


def git(git_dir: Path, *args: str, binary: bool = False) -> subprocess.CompletedProcess:
    """Runs ``git --git-dir=GIT_DIR ARGS`` and returns the finished process (not checked)."""
    return subprocess.run(
        ["git", f"--git-dir={git_dir}", *args],
        capture_output=True,
        text=not binary,
        check=False,
    )


def resolve_commit(git_dir: Path, rev: str) -> str:
    """The full id of commit ``rev`` (a tag, branch or id); :class:`CheckoutError` if none."""
    proc = git(git_dir, "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    if proc.returncode != 0:
        raise CheckoutError(f"{rev!r} is not a commit of {git_dir}")
    return proc.stdout.strip()


def tree_entries(git_dir: Path, commit: str) -> List[Entry]:
    """The blobs of ``commit``'s tree (submodule entries, which have no blob, left out)."""
    proc = git(git_dir, "ls-tree", "-r", "-z", "--full-tree", commit)
    if proc.returncode != 0:
        raise CheckoutError(f"git ls-tree failed for {commit}: {proc.stderr.strip()}")
    entries = []
    for record in proc.stdout.split("\0"):
        if not record:
            continue
        meta, path = record.split("\t", 1)
        mode, kind, oid = meta.split()
        if kind == "blob":
            entries.append(Entry(mode, oid, path))
    return entries


def safe_target(out_dir: Path, path: str) -> Path:
    """``out_dir / path``, refusing a path that would leave ``out_dir``."""
    parts = Path(path).parts
    if not parts or ".." in parts or Path(path).is_absolute():
        raise CheckoutError(f"tree path {path!r} leaves the output folder")
    # The parent resolved (a link written earlier as the entry itself is not followed).
    parent = (out_dir / path).parent.resolve()
    root = out_dir.resolve()
    if parent != root and root not in parent.parents:
        raise CheckoutError(f"tree path {path!r} leaves the output folder")
    return parent / parts[-1]


def write_entry(out_dir: Path, entry: Entry, data: bytes) -> None:
    """Writes one blob (a symbolic link for mode 120000), only when its content differs."""
    target = safe_target(out_dir, entry.path)
    target.parent.mkdir(parents=True, exist_ok=True)
    if entry.mode == "120000":
        link = os.fsdecode(data)
        if target.is_symlink() and os.readlink(target) == link:
            return
        if target.is_symlink() or target.exists():
            target.unlink()
        target.symlink_to(link)
        return
    if target.is_symlink():
        target.unlink()
    if not (target.is_file() and target.read_bytes() == data):
        target.write_bytes(data)
    target.chmod(0o755 if entry.mode == "100755" else 0o644)


def checkout(git_dir: Path, rev: str, out_dir: Path) -> List[str]:
    """Lays out ``rev`` of ``git_dir`` into ``out_dir``; returns the paths whose blob is
    missing (also written to ``out_dir/.checkout-missing``)."""
    commit = resolve_commit(git_dir, rev)
    out_dir.mkdir(parents=True, exist_ok=True)
    missing = []
    for entry in tree_entries(git_dir, commit):
        proc = git(git_dir, "cat-file", "blob", entry.oid, binary=True)
        if proc.returncode != 0:
            missing.append(entry.path)
            continue
        write_entry(out_dir, entry, proc.stdout)
    (out_dir / ".checkout-missing").write_text("".join(f"{p}\n" for p in missing))
    (out_dir / ".checkout-commit").write_text(commit + "\n")
    return missing


def main(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("git_dir", type=Path, help="a git directory (bare clone or mirror)")
    parser.add_argument("rev", help="the commit, tag or branch to lay out")
    parser.add_argument("out_dir", type=Path, help="the folder to write the tree into")
    args = parser.parse_args(argv)
    try:
        missing = checkout(args.git_dir, args.rev, args.out_dir)
    except CheckoutError as e:
        print(f"checkout_mirror: {e}", file=sys.stderr)
        return 1
    if missing:
        print(
            f"checkout_mirror: {len(missing)} blobs missing from {args.git_dir} "
            f"(listed in {args.out_dir / '.checkout-missing'}), e.g. {missing[0]}",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
