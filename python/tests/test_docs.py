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
                    target = (
                        member.__func__
                        if isinstance(member, (classmethod, staticmethod))
                        else member
                    )
                    if callable(target) or isinstance(target, property):
                        if not (target.__doc__ or "").strip():
                            missing.append(f"{name}.{member_name}")
    assert missing == []


def test_thread_safety_and_ownership_are_documented():
    assert "threads" in topoloc.Map.__doc__ and "Ownership" in topoloc.Map.__doc__
    for cls in (topoloc.Localizer, topoloc.MapBuilder, topoloc.LoopDetector):
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


def test_readme_image_example_uses_the_real_api():
    # The images example needs files, a video and OpenCV: it is compiled, not run, and every
    # topoloc name and keyword argument it uses must exist.
    text = (PYTHON_DIR / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    code = next(b for b in blocks if "build_from_image_files" in b)
    compile(code, "README.md", "exec")
    for dotted in re.findall(r"topoloc\.([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)?)", code):
        obj = topoloc
        for part in dotted.split("."):
            obj = getattr(obj, part)
    for fn in (topoloc.Map.build_from_image_files, topoloc.Localizer.process):
        params = inspect.signature(fn).parameters
        name = fn.__name__
        call = re.search(rf"{name}\((.*?)\)\n", code, re.S)
        if call:
            for kw in re.findall(r"(\w+)=", call.group(1)):
                assert kw in params, f"{name}() has no argument {kw!r}"
    for kw in re.findall(r"loc\.process\(([^)]*)\)", code)[0].split(","):
        assert kw.split("=")[0].strip() in inspect.signature(topoloc.Localizer.process).parameters
