"""The integration scripts' anchored edits (cpp-examples/*/integrate/apply.py) on synthetic
upstream trees: each tree holds exactly the anchor lines the edits expect, so these tests run
without the GPL checkouts the scripts are meant for."""

from __future__ import annotations

import hashlib
import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = {
    "orbslam": ROOT / "cpp-examples" / "orbslam" / "integrate" / "apply.py",
    "vins": ROOT / "cpp-examples" / "vins" / "integrate" / "apply.py",
}


def load(name: str, path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


APPLY = {name: load(f"topoloc_apply_{name}", path) for name, path in SCRIPTS.items()}
edits_module = sys.modules["anchored_edits"]


def synthesize(apply: ModuleType, variant: str, root: Path) -> None:
    """Writes an upstream tree holding each anchor as often as the edits of `variant` expect
    (after its narrowing line when the edit has one), the integration's marker file and the
    files it replaces."""
    integration = apply.INTEGRATION
    files: dict[str, list[str]] = {integration.marker: ["marker\n"]}
    seen: set[tuple[str, str, str | None]] = set()
    for edit in integration.edits[variant]:
        key = (edit.path, edit.anchor, edit.after)
        if key in seen:
            continue
        seen.add(key)
        lines = files.setdefault(edit.path, [])
        if edit.after is not None:
            lines += [edit.after + "\n", edit.anchor + "\n"]
        else:
            lines += [edit.anchor + "\n"] * edit.count
    for rel in integration.replaced.get(variant, {}):
        files.setdefault(rel, ["upstream's own\n"])
    for rel, lines in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text("".join(lines))


def tree_digest(root: Path) -> str:
    digest = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def cases() -> Iterator[tuple[str, str]]:
    for name in APPLY:
        for variant in ("stock", "topoloc"):
            yield name, variant


@pytest.mark.parametrize(("name", "variant"), list(cases()))
def test_apply_lays_out_every_edit_once_and_leaves_upstream_alone(
    tmp_path: Path, name: str, variant: str, capsys: pytest.CaptureFixture[str]
) -> None:
    apply = APPLY[name]
    upstream, out = tmp_path / "upstream", tmp_path / "out"
    synthesize(apply, variant, upstream)
    before = tree_digest(upstream)
    args = [str(upstream), str(out), "--variant", variant]
    assert apply.main(apply.INTEGRATION, "apply", args) == 0
    assert tree_digest(upstream) == before
    for edit in apply.INTEGRATION.edits[variant]:
        assert edit.text in (out / edit.path).read_text(), (edit.path, edit.anchor)
    for rel, ours in apply.INTEGRATION.added.get(variant, {}).items():
        assert (out / rel).read_bytes() == ours.read_bytes()
        assert not (upstream / rel).exists()
    for rel, ours in apply.INTEGRATION.replaced.get(variant, {}).items():
        assert (out / rel).read_bytes() == ours.read_bytes()
    capsys.readouterr()
    # A second run writes nothing: the build tool sees no change.
    assert apply.main(apply.INTEGRATION, "apply", args) == 0
    assert ": 0 files written" in capsys.readouterr().out


@pytest.mark.parametrize("name", list(APPLY))
@pytest.mark.parametrize("change", ["missing", "doubled"])
def test_a_tree_that_does_not_match_is_refused_before_anything_is_written(
    tmp_path: Path, name: str, change: str, capsys: pytest.CaptureFixture[str]
) -> None:
    apply = APPLY[name]
    upstream, out = tmp_path / "upstream", tmp_path / "out"
    synthesize(apply, "topoloc", upstream)
    edit = next(e for e in apply.INTEGRATION.edits["topoloc"] if e.after is None)
    path = upstream / edit.path
    text = path.read_text()
    line = edit.anchor + "\n"
    path.write_text(text.replace(line, "", 1) if change == "missing" else text + line)
    assert (
        apply.main(apply.INTEGRATION, "apply", [str(upstream), str(out), "--variant", "topoloc"])
        == 2
    )
    assert not out.exists()
    err = capsys.readouterr().err
    assert edit.path in err and repr(edit.anchor) in err


@pytest.mark.parametrize("name", list(APPLY))
def test_apply_refuses_another_checkout_and_writing_into_upstream(
    tmp_path: Path, name: str
) -> None:
    apply = APPLY[name]
    upstream = tmp_path / "upstream"
    upstream.mkdir()
    args = [str(upstream), str(tmp_path / "out"), "--variant", "stock"]
    assert apply.main(apply.INTEGRATION, "apply", args) == 2  # no marker file
    synthesize(apply, "stock", upstream)
    before = tree_digest(upstream)
    args = [str(upstream), str(upstream), "--variant", "stock"]
    assert apply.main(apply.INTEGRATION, "apply", args) == 2
    assert tree_digest(upstream) == before


def test_apply_edit_inserts_replaces_and_narrows() -> None:
    edit = edits_module.Edit
    text = "a\nanchor 1\nb\nstart\nanchor 2\n"
    apply_edit = edits_module.apply_edit
    assert apply_edit(text, edit("f", "anchor", "X\n", "before", 2), "up") == (
        "a\nX\nanchor 1\nb\nstart\nX\nanchor 2\n"
    )
    assert apply_edit(text, edit("f", "anchor", "X\n", "after", after="start"), "up") == (
        "a\nanchor 1\nb\nstart\nanchor 2\nX\n"
    )
    assert apply_edit(text, edit("f", "anchor 1", "one", "replace"), "up").startswith("a\none\n")
    with pytest.raises(edits_module.AnchorError, match="2 lines contain 'anchor', expected 1"):
        apply_edit(text, edit("f", "anchor", "X\n", "before"), "up")
    with pytest.raises(edits_module.AnchorError, match="no line contains 'nowhere'"):
        apply_edit(text, edit("f", "anchor", "X\n", "before", after="nowhere"), "up")
