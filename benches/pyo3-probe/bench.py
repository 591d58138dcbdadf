#!/usr/bin/env python3
"""Per-frame call overhead of the ctypes shim (python/topoloc) against a minimal pyo3 module
(benches/pyo3-probe), on one generated map; also whether either path copies the descriptor and
whether the GIL is released during the call. The decision it informs is written up in
python/README.md ("Why ctypes, not pyo3").

    python3 benches/pyo3-probe/bench.py            # builds the probe (cargo), then measures
    python3 benches/pyo3-probe/bench.py --json     # one JSON object instead of the tables

The probe is built with `cargo build --release --manifest-path benches/pyo3-probe/Cargo.toml`
into the repository's target directory (CARGO_TARGET_DIR if set), which it shares with the main
workspace so that topoloc and its dependencies are not compiled twice. The shim is imported
from this checkout's python/ directory unless --installed is given (then from wherever
`import topoloc` finds it).

Every figure is the median of many single calls timed with perf_counter_ns, variants
interleaved round by round so that a noisy neighbour hits them alike.
"""

from __future__ import annotations

import argparse
import ctypes
import importlib.machinery
import importlib.util
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Tuple

import numpy as np

PROBE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PROBE_DIR.parents[1]


#: The tiny map: places x views per place.
TINY = (5, 2)
SHIM = "ctypes shim Localizer.process"
RAW = "raw ctypes topoloc_localizer_process"
PYO3 = "pyo3 probe process (GIL held)"
PYO3_DETACHED = "pyo3 probe process_detached (GIL released)"
INNER = "Rust localize, timed inside Rust (probe build)"


class ProbeBuildError(RuntimeError):
    """The pyo3 probe could not be built or found."""


def build_probe(skip: bool) -> Path:
    """Builds the probe and returns the path of its extension module."""
    env = dict(os.environ)
    env.setdefault("CARGO_TARGET_DIR", str(REPO_ROOT / "target"))
    target = Path(env["CARGO_TARGET_DIR"])
    built = target / "release" / "libtopoloc_pyo3_probe.so"
    if not skip:
        cargo = env.get("CARGO") or shutil.which("cargo")
        if cargo is None:
            raise ProbeBuildError("`cargo` was not found on PATH (nor $CARGO): install Rust to build the pyo3 probe")
        cmd = [cargo, "build", "--release", "--quiet", "--manifest-path", str(PROBE_DIR / "Cargo.toml")]
        proc = subprocess.run(cmd, env=env)
        if proc.returncode != 0:
            raise ProbeBuildError(f"{' '.join(cmd)} failed with exit code {proc.returncode}")
    if not built.is_file():
        raise ProbeBuildError(f"{built} does not exist (build the probe without --no-build)")
    return built


def import_probe(built: Path, tmp: Path) -> Any:
    """Imports the probe's cdylib as the extension module ``topoloc_pyo3_probe``."""
    module = tmp / "topoloc_pyo3_probe.abi3.so"
    shutil.copyfile(built, module)
    loader = importlib.machinery.ExtensionFileLoader("topoloc_pyo3_probe", str(module))
    spec = importlib.util.spec_from_file_location("topoloc_pyo3_probe", module, loader=loader)
    assert spec is not None
    mod = importlib.util.module_from_spec(spec)
    loader.exec_module(mod)
    return mod


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def make_map(topoloc: Any, path: Path, places: int, views_per_place: int, dim: int, seed: int) -> np.ndarray:
    """A corridor of ``places`` places with ``views_per_place`` random unit views each (as the
    Python tests build maps), saved to ``path``; returns the (V, D) view descriptors."""
    rng = np.random.default_rng(seed)
    views = unit(rng.standard_normal((places * views_per_place, dim))).astype(np.float32)
    with topoloc.MapBuilder("bench", "random-unit", dim) as b:
        for p in range(places):
            b.add_place(position=[2.0 * p, 0.0, 0.0])
            for k in range(views_per_place):
                b.add_view(p, views[p * views_per_place + k])
            if p:
                b.add_edge(p - 1, p)
        with b.build() as m:
            m.save(path)
    return views


def queries(views: np.ndarray, n: int, seed: int) -> List[np.ndarray]:
    """``n`` noisy copies of views along the corridor, C-contiguous float32 (the zero-copy case)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        v = views[(i * 3) % len(views)]
        out.append(np.ascontiguousarray(v + 0.05 * rng.standard_normal(v.size), dtype=np.float32))
    return out


class Clock:
    """Monotonic timestamps for localizers in filter mode (one shared counter is enough)."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        self.t += 0.1
        return self.t


def time_calls(variants: Dict[str, Callable[[np.ndarray, float], Any]],
               batches: Dict[str, Callable[[np.ndarray, int], List[float]]],
               qs: List[np.ndarray], rounds: int, per_round: int, clock: Clock) -> Dict[str, List[float]]:
    """Nanoseconds of each single call, variants interleaved round by round (order rotated).
    ``batches`` time ``per_round`` calls themselves (inside Rust) and run in the same rounds."""
    names = list(variants) + list(batches)
    samples: Dict[str, List[float]] = {n: [] for n in names}
    perf = time.perf_counter_ns
    for r in range(rounds):
        order = names[r % len(names):] + names[: r % len(names)]
        for name in order:
            out = samples[name]
            if name in batches:
                out += [x * 1e9 for x in batches[name](qs[r % len(qs)], per_round)]
                continue
            fn = variants[name]
            for i in range(per_round):
                q = qs[i % len(qs)]
                t = clock()
                start = perf()
                fn(q, t)
                out.append(perf() - start)
    return samples


def zero_copy_checks(topoloc: Any, loc: Any, probe: Any, clock: Clock, dim: int) -> Dict[str, Dict[str, Any]]:
    """Whether each path hands the caller's descriptor memory to the library or a copy."""
    from topoloc import _lib  # the shim's C calls go through _lib.lib

    seen: Dict[str, int] = {}
    real = _lib.lib.topoloc_localizer_process

    def spy(handle: Any, frame_ref: Any, result_ref: Any) -> int:
        seen["address"] = ctypes.cast(frame_ref._obj.descriptor, ctypes.c_void_p).value or 0
        return real(handle, frame_ref, result_ref)

    rng = np.random.default_rng(99)
    base = unit(rng.standard_normal(2 * dim)).astype(np.float32)
    cases = {
        "float32 contiguous": np.ascontiguousarray(base[:dim]),
        "float32 strided view (a[::2])": base[::2],
        "float64 contiguous": np.ascontiguousarray(base[:dim], dtype=np.float64),
    }
    out: Dict[str, Dict[str, Any]] = {}
    _lib.lib.topoloc_localizer_process = spy
    try:
        for case, arr in cases.items():
            loc.process(arr, timestamp=clock())
            shim = "borrowed" if seen["address"] == arr.ctypes.data else "copied"
            try:
                probe.process(arr, clock())
                pyo3 = "borrowed" if probe.last_address == arr.ctypes.data and not probe.last_copied else "copied"
            except TypeError as e:
                pyo3 = f"refused (TypeError: {str(e).splitlines()[0][:60]})"
            out[case] = {"ctypes shim": shim, "pyo3 probe": pyo3}
    finally:
        _lib.lib.topoloc_localizer_process = real
    return out


def thread_scaling(make_call: Callable[[], Callable[[np.ndarray, float], Any]], qs: List[np.ndarray],
                   calls: int) -> Tuple[float, float]:
    """(seconds for one thread doing ``calls`` calls, seconds for two threads doing ``calls``
    each at once); each thread has its own localizer. Two-thread / one-thread near 1.0 means the
    calls ran in parallel (GIL released), near 2.0 that they were serialized (GIL held)."""

    def worker(fn: Callable[[np.ndarray, float], Any], barrier: threading.Barrier) -> None:
        barrier.wait()
        t = 0.0
        for i in range(calls):
            t += 0.1
            fn(qs[i % len(qs)], t)

    def run(n_threads: int) -> float:
        fns = [make_call() for _ in range(n_threads)]
        barrier = threading.Barrier(n_threads + 1)
        threads = [threading.Thread(target=worker, args=(fn, barrier)) for fn in fns]
        for th in threads:
            th.start()
        start = time.perf_counter()
        barrier.wait()
        for th in threads:
            th.join()
        return time.perf_counter() - start

    one = min(run(1) for _ in range(3))
    two = min(run(2) for _ in range(3))
    return one, two


def measure(topoloc: Any, _lib: Any, probe_mod: Any, map_path: Path, qs: List[np.ndarray],
            args: argparse.Namespace, clock: Clock) -> Dict[str, float]:
    """Median microseconds per call of every variant on the map at ``map_path``."""
    m = topoloc.Map.load(map_path)
    loc = topoloc.Localizer(m)
    probe = probe_mod.Probe(str(map_path))

    # Same answers on the same frames (from a fresh state).
    for i, q in enumerate(qs[:50]):
        a = loc.process(q, timestamp=float(i))
        b = probe.process(q, float(i))
        if (a.place, a.view) != (b.place, b.view) or abs(a.confidence - b.confidence) > 1e-6:
            raise SystemExit(f"the shim and the probe disagree on frame {i}: {a} vs place {b.place} view {b.view}")
    clock.t = max(clock.t, 100.0)

    # A raw ctypes call with prepared structs: the FFI's own cost, without the shim's work.
    frame = _lib.topoloc_frame()
    result = _lib.topoloc_result()
    cands = (_lib.topoloc_candidate * 5)()
    raw_loc = topoloc.Localizer(m)
    handle = raw_loc._ptr
    c_process = _lib.lib.topoloc_localizer_process
    f32p = ctypes.POINTER(ctypes.c_float)
    frame_ref, result_ref = ctypes.byref(frame), ctypes.byref(result)

    def raw_ctypes(q: np.ndarray, t: float) -> int:
        frame.struct_size = ctypes.sizeof(frame)
        frame.timestamp = t
        frame.descriptor = q.ctypes.data_as(f32p)
        frame.descriptor_len = q.size
        result.struct_size = ctypes.sizeof(result)
        result.candidates = cands
        result.candidates_capacity = 5
        return c_process(handle, frame_ref, result_ref)

    abi = _lib.lib.topoloc_abi_version

    def py_noop(q: np.ndarray, t: float) -> None:
        return None

    variants: Dict[str, Callable[[np.ndarray, float], Any]] = {
        "python no-op function": py_noop,
        "ctypes no-op (topoloc_abi_version())": lambda q, t: abi(),
        "pyo3 no-op (same arguments)": probe.noop,
        SHIM: lambda q, t: loc.process(q, timestamp=t),
        RAW: raw_ctypes,
        PYO3: probe.process,
        PYO3_DETACHED: probe.process_detached,
    }
    inner_probe = probe_mod.Probe(str(map_path))

    def inner(q: np.ndarray, n: int) -> List[float]:
        inner_probe.reset()  # its own timestamps: 0, 1, 2, ...
        return list(inner_probe.inner_seconds(q, 0.0, n))

    batches = {INNER: inner}
    for fn in variants.values():  # warm-up
        for q in qs[:50]:
            fn(q, clock())
    samples = time_calls(variants, batches, qs, args.rounds, args.per_round, clock)
    raw_loc.close()
    loc.close()
    m.close()
    return {n: statistics.median(s) / 1000.0 for n, s in samples.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--places", type=int, default=250)
    ap.add_argument("--views-per-place", type=int, default=4)
    ap.add_argument("--dim", type=int, default=512)
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--per-round", type=int, default=500, help="calls per variant per round")
    ap.add_argument("--thread-calls", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-build", action="store_true", help="use the probe already built")
    ap.add_argument("--installed", action="store_true", help="import topoloc as installed, not from python/")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    if not args.installed:
        sys.path.insert(0, str(REPO_ROOT / "python"))
    import topoloc
    from topoloc import _lib

    with tempfile.TemporaryDirectory(prefix="topoloc-pyo3-probe-") as tmp_name:
        tmp = Path(tmp_name)
        probe_mod = import_probe(build_probe(args.no_build), tmp)
        if probe_mod.TOPOLOC_VERSION != topoloc.version():
            raise SystemExit(f"probe built from topoloc {probe_mod.TOPOLOC_VERSION}, shim loads {topoloc.version()}")
        clock = Clock()
        # A tiny map, where the localization work is a few microseconds and a call's time is
        # mostly its binding's overhead; then the realistic one.
        tiny_path = tmp / "tiny.topoloc"
        tiny_views = make_map(topoloc, tiny_path, TINY[0], TINY[1], args.dim, args.seed)
        tiny = measure(topoloc, _lib, probe_mod, tiny_path, queries(tiny_views, 256, args.seed + 1), args, clock)
        map_path = tmp / "bench.topoloc"
        views = make_map(topoloc, map_path, args.places, args.views_per_place, args.dim, args.seed)
        qs = queries(views, 256, args.seed + 1)
        med = measure(topoloc, _lib, probe_mod, map_path, qs, args, clock)

        m = topoloc.Map.load(map_path)
        loc = topoloc.Localizer(m)
        probe = probe_mod.Probe(str(map_path))
        copies = zero_copy_checks(topoloc, loc, probe, clock, args.dim)

        def shim_call() -> Callable[[np.ndarray, float], Any]:
            own = topoloc.Localizer(m)
            return lambda q, t: own.process(q, timestamp=t)

        def pyo3_held() -> Callable[[np.ndarray, float], Any]:
            return probe_mod.Probe(str(map_path)).process

        def pyo3_detached() -> Callable[[np.ndarray, float], Any]:
            return probe_mod.Probe(str(map_path)).process_detached

        threads = {
            "ctypes shim": thread_scaling(shim_call, qs, args.thread_calls),
            "pyo3 probe, GIL held": thread_scaling(pyo3_held, qs, args.thread_calls),
            "pyo3 probe, detach": thread_scaling(pyo3_detached, qs, args.thread_calls),
        }
        loc.close()
        m.close()

    bindings = {
        "ctypes shim": SHIM,
        "raw ctypes": RAW,
        "pyo3 probe, GIL held": PYO3,
        "pyo3 probe, detach": PYO3_DETACHED,
    }
    overhead = {name: tiny[key] - tiny[INNER] for name, key in bindings.items()}
    report = {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_implementation()} "
                   f"{platform.python_version()}, numpy {np.__version__}",
        "maps": {
            "tiny": {"views": TINY[0] * TINY[1], "dim": args.dim},
            "realistic": {"places": args.places, "views": args.places * args.views_per_place, "dim": args.dim},
        },
        "calls_per_variant": args.rounds * args.per_round,
        "median_us": {"tiny": tiny, "realistic": med},
        "binding_overhead_us": overhead,
        "overhead_share_of_realistic_call": {n: overhead[n] / med[k] for n, k in bindings.items()},
        "descriptor": copies,
        "two_threads_over_one": {k: {"one_s": a, "two_s": b, "ratio": b / a} for k, (a, b) in threads.items()},
        "library": topoloc.library_path,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    views_n = report["maps"]["realistic"]["views"]
    print(f"machine: {report['machine']}")
    print(f"maps: tiny {TINY[0] * TINY[1]} views, realistic {args.places} places x {args.views_per_place} views = "
          f"{views_n} views; D = {args.dim}; {report['calls_per_variant']} calls per variant and map\n")
    shim = med[SHIM]
    print(f"| call (median) | tiny map, us | {views_n}-view map, us | / shim ({views_n} views) |")
    print("| --- | ---: | ---: | ---: |")
    for name in med:
        print(f"| {name} | {tiny[name]:.2f} | {med[name]:.2f} | {med[name] / shim:.3f} |")
    print(f"\n| binding | overhead per call, us (tiny-map call - Rust work) | share of a {views_n}-view call |")
    print("| --- | ---: | ---: |")
    for name in bindings:
        print(f"| {name} | {overhead[name]:.2f} | {report['overhead_share_of_realistic_call'][name]:.1%} |")
    print("\n| descriptor passed | ctypes shim | pyo3 probe |")
    print("| --- | --- | --- |")
    for case, r in copies.items():
        print(f"| {case} | {r['ctypes shim']} | {r['pyo3 probe']} |")
    print(f"\n| {args.thread_calls} calls per thread ({views_n}-view map, own localizer each) | 1 thread, s | 2 threads, s | 2 / 1 |")
    print("| --- | ---: | ---: | ---: |")
    for name, r in report["two_threads_over_one"].items():
        print(f"| {name} | {r['one_s']:.3f} | {r['two_s']:.3f} | {r['ratio']:.2f} |")
    print("\n(2 / 1 near 1.0: the two threads ran in parallel, the GIL released during the call; near 2.0: serialized)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
