"""Anchored edits of an upstream source tree, shared by the integration scripts
(`orbslam/integrate/apply.py`, `vins/integrate/apply.py`).

An edit names an anchor, a short line of the upstream code, and the number of times it must
occur; a tree where an anchor is missing or occurs a different number of times is refused with
the file and the anchor (`AnchorError`) before anything is written. The output tree is written
file by file, only where the content changes, so a second run rebuilds nothing. The upstream
checkout is never modified.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

# Build outputs and version control, wherever they are (upstream trees keep no sources there).
SKIPPED_DIRS = {".git", "build", "lib", "devel"}


@dataclass(frozen=True)
class Edit:
    """Inserts `text` before or after each line that contains `anchor`, or replaces `anchor`
    inside those lines. `after` first narrows the search to the lines following the first line
    that contains it. `count` is how many lines must contain the anchor."""

    path: str
    anchor: str
    text: str
    where: str  # "before", "after" or "replace"
    count: int = 1
    after: str | None = None


class AnchorError(Exception):
    """The upstream tree does not match an edit (a missing file, an anchor seen a different
    number of times than expected)."""


def apply_edit(text: str, edit: Edit, upstream_name: str) -> str:
    """`text` with `edit` applied; raises `AnchorError` naming `upstream_name` on a mismatch."""
    lines = text.splitlines(keepends=True)
    start = 0
    if edit.after is not None:
        starts = [i for i, line in enumerate(lines) if edit.after in line]
        if not starts:
            raise AnchorError(f"{edit.path}: no line contains {edit.after!r}")
        start = starts[0] + 1
    hits = [i for i in range(start, len(lines)) if edit.anchor in lines[i]]
    if edit.after is not None:
        hits = hits[:1]  # the first one after the narrowing line
    if len(hits) != edit.count:
        raise AnchorError(
            f"{edit.path}: {len(hits)} lines contain {edit.anchor!r}, expected {edit.count}"
            f" (is this {upstream_name}?)"
        )
    for i in reversed(hits):
        if edit.where == "replace":
            lines[i] = lines[i].replace(edit.anchor, edit.text)
        elif edit.where == "before":
            lines[i:i] = [edit.text]
        elif edit.where == "after":
            lines[i + 1 : i + 1] = [edit.text]
        else:
            raise ValueError(edit.where)
    return "".join(lines)


def desired_files(
    upstream: Path,
    edits: Iterable[Edit],
    replaced: Mapping[str, Path],
    upstream_name: str,
    added: Mapping[str, Path] | None = None,
) -> dict[str, bytes]:
    """The content of every file of the output tree that differs from upstream's: the edited
    files, the upstream files `replaced` by one of ours (path in the tree -> our file; the
    upstream file must exist) and our files `added` (must not exist upstream)."""
    out: dict[str, bytes] = {}
    for edit in edits:
        path = upstream / edit.path
        if not path.is_file():
            raise AnchorError(f"{edit.path}: not in {upstream} (is this {upstream_name}?)")
        if edit.path not in out:
            out[edit.path] = path.read_bytes()
        text = out[edit.path].decode("utf-8", errors="surrogateescape")
        out[edit.path] = apply_edit(text, edit, upstream_name).encode(
            "utf-8", errors="surrogateescape"
        )
    for rel, source in replaced.items():
        if not (upstream / rel).is_file():
            raise AnchorError(f"{rel}: not in {upstream} (is this {upstream_name}?)")
        out[rel] = source.read_bytes()
    for rel, source in (added or {}).items():
        if (upstream / rel).exists():
            raise AnchorError(f"{rel}: already in {upstream} (is this {upstream_name}?)")
        out[rel] = source.read_bytes()
    return out


def write_if_changed(path: Path, content: bytes, mode: int | None = None) -> bool:
    """Writes `content` to `path` atomically unless it is already there; True if written."""
    if path.is_file() and path.read_bytes() == content:
        return False
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".topoloc-tmp")
    tmp.write_bytes(content)
    if mode is not None:
        os.chmod(tmp, mode)
    os.replace(tmp, path)
    return True


def lay_out(upstream: Path, out: Path, changed: Mapping[str, bytes]) -> int:
    """Writes OUT: upstream's files, those of `changed` with their new content, and the files of
    `changed` that upstream lacks. Returns how many files were written."""
    written = 0
    seen: set[str] = set()
    for root, dirs, files in os.walk(upstream):
        rel_root = Path(root).relative_to(upstream)
        dirs[:] = [d for d in dirs if d not in SKIPPED_DIRS]
        for name in files:
            rel = (rel_root / name).as_posix()
            source = upstream / rel
            if source.is_symlink():
                continue
            seen.add(rel)
            content = changed.get(rel)
            if content is None:
                content = source.read_bytes()
            written += write_if_changed(out / rel, content, source.stat().st_mode & 0o777)
    for rel, content in changed.items():
        if rel not in seen:
            written += write_if_changed(out / rel, content, 0o644)
    return written


def fingerprint(variant: str, changed: Mapping[str, bytes]) -> str:
    """A short hash of the variant and of every changed file: equal trees, equal prints."""
    digest = hashlib.sha256(variant.encode())
    for rel, content in sorted(changed.items()):
        digest.update(rel.encode() + b"\0" + content)
    return digest.hexdigest()[:16]


@dataclass(frozen=True)
class Integration:
    """What an apply.py lays out: the upstream project's name, a file every checkout of it has,
    the edits of each variant and our files replacing or added to upstream's."""

    upstream_name: str
    marker: str
    edits: Mapping[str, list[Edit]]
    replaced: Mapping[str, Mapping[str, Path]]
    added: Mapping[str, Mapping[str, Path]]


def main(integration: Integration, description: str, argv: list[str] | None = None) -> int:
    """The command line of an apply.py: `UPSTREAM OUT --variant V`; exit status 2 for a tree
    that is not the expected checkout or does not match an anchor (OUT is then untouched)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("upstream", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--variant", choices=sorted(integration.edits), required=True)
    args = parser.parse_args(argv)
    upstream = args.upstream.resolve()
    name = integration.upstream_name
    if not (upstream / integration.marker).is_file():
        print(f"apply.py: {upstream} is not {name} (no {integration.marker})", file=sys.stderr)
        return 2
    if args.out.resolve() == upstream:
        print("apply.py: OUT must differ from UPSTREAM (never modified)", file=sys.stderr)
        return 2
    variant = args.variant
    try:
        changed = desired_files(  # raises before OUT is touched
            upstream,
            integration.edits[variant],
            integration.replaced.get(variant, {}),
            name,
            integration.added.get(variant, {}),
        )
        written = lay_out(upstream, args.out, changed)
    except AnchorError as e:
        print(f"apply.py: {e}", file=sys.stderr)
        return 2
    print(
        f"apply.py: {variant} tree in {args.out}: {written} files written "
        f"(edits {fingerprint(variant, changed)})"
    )
    return 0
