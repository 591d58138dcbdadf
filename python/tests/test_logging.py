"""Host logging (ABI 1.13): the library's records reach Python's ``logging`` under ``topoloc.*``
loggers, filtered inside the library by :func:`topoloc.set_log_level`; the library writes nothing
to stdout or stderr on its own."""

from __future__ import annotations

import logging
import os
import subprocess
import sys

import pytest

import topoloc

from conftest import PACKAGE_PARENT


@pytest.fixture
def restore_level():
    before = topoloc.log_level()
    yield
    topoloc.set_log_level(before if before is not None else logging.WARNING)


def test_warning_is_the_default_level():
    assert topoloc.log_level() == logging.WARNING


def test_records_reach_logging_up_to_the_level(corridor, tmp_path, caplog, restore_level):
    path = tmp_path / "logged.topoloc"
    topoloc.set_log_level(logging.INFO)
    with caplog.at_level(topoloc.TRACE, logger="topoloc"):
        corridor.map.save(path)
        topoloc.Map.load(path).close()
    infos = [r for r in caplog.records if r.name == "topoloc.map.file"]
    assert [r.levelno for r in infos] == [logging.INFO, logging.INFO], caplog.records
    assert infos[0].getMessage().startswith(f"saved {path}: 12 places, 24 views")
    assert infos[1].getMessage().startswith(f"loaded {path}: 12 places, 24 views, D = 64")

    caplog.clear()
    topoloc.set_log_level(logging.WARNING)  # info records are dropped inside the library
    with caplog.at_level(topoloc.TRACE, logger="topoloc"):
        topoloc.Map.load(path).close()
    assert [r for r in caplog.records if r.name.startswith("topoloc")] == []


def test_trace_gives_one_record_per_frame(corridor, caplog, restore_level):
    topoloc.set_log_level(topoloc.TRACE)
    with caplog.at_level(topoloc.TRACE, logger="topoloc"), topoloc.Localizer(corridor.map) as loc:
        for i in range(3):
            loc.process(corridor.query(i), timestamp=float(i))
    frames = [r for r in caplog.records if r.name == "topoloc.localize.localizer"]
    assert [r.levelno for r in frames] == [topoloc.TRACE] * 3
    assert frames[2].getMessage().startswith("frame 2 (t = 2): place ")


def test_off_stops_every_record(corridor, tmp_path, caplog, restore_level):
    topoloc.set_log_level(logging.CRITICAL + 1)
    assert topoloc.log_level() == logging.CRITICAL + 1
    with caplog.at_level(topoloc.TRACE, logger="topoloc"):
        corridor.map.save(tmp_path / "quiet.topoloc")
    assert [r for r in caplog.records if r.name.startswith("topoloc")] == []


def test_concurrent_use_status_has_its_class():
    assert topoloc.status_name(6) == "TOPOLOC_ERR_CONCURRENT_USE"
    assert issubclass(topoloc.ConcurrentUseError, topoloc.TopolocError)


def test_the_library_prints_nothing_on_its_own(tmp_path):
    """Save, load (a stale temporary file cleaned up: a warning record), localize, a failing
    load: in a child process without logging configured nothing reaches stdout or stderr when
    the bridge is off, and the warning shows through Python's logging when it is on."""
    stale = tmp_path / ".m.topoloc.topoloc-tmp-Ab12Cd"
    script = f"""
import logging, sys, numpy as np, topoloc
if sys.argv[1] == "off":
    topoloc.set_log_level(logging.CRITICAL + 1)
with topoloc.MapBuilder("toy", None, 4) as b:
    for i in range(3):
        b.add_place(); b.add_view(i, np.eye(4)[i] + 0.1)
    b.add_edge(0, 1)
    m = b.build()
open({str(stale)!r}, "wb").write(b"half a map")
m.save({str(tmp_path / "m.topoloc")!r})
m = topoloc.Map.load({str(tmp_path / "m.topoloc")!r})
with topoloc.Localizer(m) as loc:
    for t in range(5):
        loc.process(np.eye(4, dtype=np.float32)[t % 3] + 0.1, timestamp=float(t))
try:
    topoloc.Map.load({str(tmp_path / "missing.topoloc")!r})
except topoloc.MapIOError:
    pass
"""
    env = dict(os.environ, PYTHONPATH=str(PACKAGE_PARENT))
    run = lambda mode: subprocess.run(  # noqa: E731
        [sys.executable, "-c", script, mode], env=env, capture_output=True, text=True, timeout=120
    )
    quiet = run("off")
    assert quiet.returncode == 0, quiet.stderr
    assert (quiet.stdout, quiet.stderr) == ("", "")
    default = run("default")
    assert default.returncode == 0, default.stderr
    assert default.stdout == ""
    assert "removed" in default.stderr and "interrupted save" in default.stderr, default.stderr
    assert not stale.exists()
