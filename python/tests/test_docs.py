"""Documentation: every public name is documented, and the README example runs."""

from __future__ import annotations

import inspect
import re


import topoloc

from conftest import PYTHON_DIR


def test_every_public_name_has_a_docstring():
    missing = []
    for name in topoloc.__all__:
        obj = getattr(topoloc, name)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            if not (obj.__doc__ or "").strip():
                missing.append(name)
            if inspect.isclass(obj) and not issubclass(obj, BaseException):
                for member_name, member in vars(obj).items():
                    if member_name.startswith("_"):
                        continue
                    target = member.__func__ if isinstance(member, (classmethod, staticmethod)) else member
                    if callable(target) or isinstance(target, property):
                        if not (target.__doc__ or "").strip():
                            missing.append(f"{name}.{member_name}")
    assert missing == []


def test_thread_safety_and_ownership_are_documented():
    assert "threads" in topoloc.Map.__doc__ and "Ownership" in topoloc.Map.__doc__
    for cls in (topoloc.Localizer, topoloc.MapBuilder):
        doc = " ".join(cls.__doc__.split())
        assert "one thread at a time" in doc and "Ownership" in doc


def test_readme_example_runs(tmp_path, monkeypatch, capsys):
    text = (PYTHON_DIR / "README.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[:3] for line in lines] == [[str(i), str(i), str(i)] for i in range(4)]
    assert (tmp_path / "corridor.topomap").is_file()
