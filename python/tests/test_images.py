"""Images in: maps built from numpy images and image files store their describer (also through
save/load), localizers describe image frames with it, progress callbacks report, cancel and
re-raise, bad images give typed errors before or inside the library and leave the localizer
unchanged, strided arrays are read in place; image maps' keypoints, their scene points and the
pose fixes they give (ABI 1.6). The VLAD backend needs nothing and always runs; the ONNX cases
run when scripts/setup-models.sh has filled ~/.cache/topoloc (skipped otherwise; failed under
CI=true, see conftest.require_models)."""

from __future__ import annotations

import ctypes
import dataclasses
import threading
import traceback
from pathlib import Path
from typing import List

import numpy as np
import pytest

import topoloc
from topoloc import _convert, _lib

from conftest import require_models, skip_or_fail

W, H = 320, 240
PLACES = 12
ONNX_MODEL = Path.home() / ".cache" / "topoloc" / "models" / "mobilenetv2-mlf-int8.onnx"


def place_image(seed: int, w: int = W, h: int = H) -> np.ndarray:
    """A deterministic textured grey "place": a horizontal ramp under 150 rectangles of random
    shades and sizes."""
    rng = np.random.default_rng(seed)
    img = np.tile((np.arange(w) * 255 // w // 2 + 40).astype(np.uint8), (h, 1))
    for _ in range(150):
        x0, y0 = rng.integers(0, w), rng.integers(0, h)
        rw, rh = rng.integers(6, 56, size=2)
        img[y0 : y0 + rh, x0 : x0 + rw] = rng.integers(0, 256)
    return img


def revisit(img: np.ndarray, seed: int) -> np.ndarray:
    """The same place seen again: shifted 3 pixels left, 10% brighter plus 10, with noise."""
    rng = np.random.default_rng(seed)
    shifted = np.concatenate([img[:, 3:], np.repeat(img[:, -1:], 3, axis=1)], axis=1).astype(
        np.int32
    )
    noisy = shifted * 11 // 10 + 10 + rng.integers(-8, 8, size=img.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8)


def colour(img: np.ndarray, seed: int) -> np.ndarray:
    """An RGB image whose channels differ: the grey image, a shifted copy and its negative."""
    return np.stack([img, np.roll(img, seed + 5, axis=1), 255 - img], axis=-1)


def write_pgm(path: Path, img: np.ndarray) -> None:
    path.write_bytes(b"P5\n%d %d\n255\n" % (img.shape[1], img.shape[0]) + img.tobytes())


def write_ppm(path: Path, rgb: np.ndarray) -> None:
    path.write_bytes(
        b"P6\n%d %d\n255\n" % (rgb.shape[1], rgb.shape[0]) + np.ascontiguousarray(rgb).tobytes()
    )


@pytest.fixture(scope="module")
def images() -> List[np.ndarray]:
    return [place_image(1000 + i) for i in range(PLACES)]


@pytest.fixture(scope="module")
def vlad_map(images):
    # No learned weights at all: VLAD of ORB, with ORB keypoints for verification (the default
    # local features, XFeat, need its network).
    m = topoloc.Map.build_from_images(images, backend="vlad-orb", threads=2, local_features="orb")
    yield m
    m.close()


def answer(r: topoloc.Result) -> topoloc.Result:
    """A result without its frame index, to compare single-frame answers to different frames."""
    return dataclasses.replace(r, frame_index=0)


# ---------------------------------------------------------------------------------------------
# Maps from images, localizing image frames
# ---------------------------------------------------------------------------------------------


def test_vlad_map_from_numpy_images(vlad_map):
    m = vlad_map
    assert (m.place_count, m.view_count, m.edge_count) == (PLACES, PLACES, PLACES - 1)
    assert m.descriptor_kind == "vlad-orb"
    assert m.dim == PLACES - 1  # dim 512 capped at images - 1
    assert m.view_info(3).keyframe_id == 3 and m.view_info(3).place == 3  # image index kept
    assert m.view_image(3) == ""  # pixels in memory: no path
    assert list(m.neighbours(5)) == [4, 6]  # a sequence: consecutive places chained


def test_revisits_are_localized_single_frame(vlad_map, images):
    with topoloc.Localizer(vlad_map, mode="single_frame") as loc:
        assert loc.options["image_backend"] == "auto"
        found = []
        for p, img in enumerate(images):
            r = loc.process(image=revisit(img, 100 + p), timestamp=float(p))
            found.append(r.place)
            assert r.candidates[0].place == r.place and 0 < r.confidence <= 1
        correct = sum(f == p for p, f in enumerate(found))
        assert correct >= PLACES - 1, found


def test_revisits_are_followed_in_filter_mode(vlad_map, images):
    with topoloc.Localizer(vlad_map) as loc:
        results = [
            loc.process(image=revisit(img, 200 + p), timestamp=0.1 * p)
            for p, img in enumerate(images)
        ]
    assert [r.place for r in results] == list(range(PLACES))
    assert [r.frame_index for r in results] == list(range(PLACES))


def test_image_frames_and_descriptor_frames_mix(vlad_map, images):
    with topoloc.Localizer(vlad_map, mode="single_frame") as loc:
        assert loc.process(vlad_map.view_descriptor(4), 0.0).place == 4
        assert loc.process(image=images[7], timestamp=1.0).place == 7
        assert loc.process(vlad_map.view_descriptor(2), timestamp=2.0).place == 2


def test_colour_formats(vlad_map, images):
    grey = revisit(images[5], 9)
    with topoloc.Localizer(vlad_map, mode="single_frame") as loc:
        expected = loc.process(image=grey, timestamp=0.0)
        assert expected.place == 5
        # Equal channels: every colour layout describes like the grey image.
        rgb = np.repeat(grey[:, :, None], 3, axis=2)
        rgba = np.concatenate([rgb, np.full_like(grey[:, :, None], 255)], axis=2)
        for img, fmt in [
            (grey[:, :, None], None),
            (rgb, None),
            (rgb, "rgb"),
            (rgb, "bgr"),
            (rgba, None),
            (rgba, "rgba"),
            (rgba, "bgra"),
        ]:
            r = loc.process(image=img, pixel_format=fmt, timestamp=0.0)
            assert r.place == 5 and r.similarity == pytest.approx(expected.similarity, abs=1e-3), (
                fmt
            )
        # Distinct channels: the same pixels in RGB and in BGR order give the same answer.
        c = colour(images[3], 3)
        a = loc.process(image=c, timestamp=0.0)
        assert answer(
            loc.process(image=c[:, :, ::-1], pixel_format="bgr", timestamp=0.0)
        ) == answer(a)
        bgra = np.concatenate([c[:, :, ::-1], np.zeros_like(c[:, :, :1])], axis=2)
        assert answer(loc.process(image=bgra, pixel_format="BGRA", timestamp=0.0)) == answer(a)


def test_views_per_place_groups_consecutive_images(images):
    m = topoloc.Map.build_from_images(
        images, backend="vlad-orb", views_per_place=2, dim=8, threads=2
    )
    with m:
        assert (m.place_count, m.view_count, m.dim) == (PLACES // 2, PLACES, 8)
        assert list(m.place_views(2)) == [4, 5]


def test_pca_rows_are_i8_by_default_and_f32_on_request(vlad_map, images, tmp_path):
    assert "/i8 fit=" in vlad_map.descriptor_model
    with topoloc.Map.build_from_images(
        images, backend="vlad-orb", threads=2, pca_precision="f32"
    ) as m:
        assert "/i8" not in m.descriptor_model
        exact, small = tmp_path / "f32.topoloc", tmp_path / "i8.topoloc"
        m.save(exact)
        vlad_map.save(small)
        assert small.stat().st_size < exact.stat().st_size
        with topoloc.Localizer(m, mode="single_frame") as loc:
            assert loc.process(image=revisit(images[4], 7), timestamp=0.0).place == 4
    with pytest.raises(topoloc.InvalidArgumentError, match="pca_precision"):
        topoloc.Map.build_from_images(images, backend="vlad-orb", pca_precision="f16")


def test_vlad_sift_backend(images):
    with topoloc.Map.build_from_images(images[:6], backend="vlad_sift", threads=2) as m:
        assert m.descriptor_kind == "vlad-sift" and m.dim == 5
        with topoloc.Localizer(m, mode="single_frame", image_backend="vlad-sift") as loc:
            assert loc.process(image=revisit(images[2], 1), timestamp=0.0).place == 2


# ---------------------------------------------------------------------------------------------
# Progress, cancellation, exceptions in the callback
# ---------------------------------------------------------------------------------------------


def test_progress_is_reported_on_the_calling_thread(images):
    seen, threads = [], set()

    def progress(stage, done, total):
        seen.append((stage, done, total))
        threads.add(threading.get_ident())
        # returns None: goes on

    with topoloc.Map.build_from_images(images[:8], backend="vlad-orb", progress=progress) as m:
        assert m.place_count == 8
    assert seen[0][0] == "describing"
    assert ("describing", 8, 8) in seen
    assert seen[-1] == ("fitting", 1, 1)
    assert {s for s, _, _ in seen} == {"describing", "fitting"}
    assert all(0 <= d <= t for _, d, t in seen)
    assert threads == {threading.get_ident()}


@pytest.mark.parametrize("stop_at", ["describing", "fitting"])
def test_progress_returning_false_cancels(images, stop_at):
    calls = []

    def progress(stage, done, total):
        calls.append(stage)
        return stage != stop_at

    with pytest.raises(topoloc.CancelledError) as e:
        topoloc.Map.build_from_images(images[:6], backend="vlad-orb", progress=progress)
    assert e.value.status == 305 and "cancel" in e.value.message
    assert calls[-1] == stop_at and calls.count(stop_at) == 1  # not called again after False


class Boom(Exception):
    pass


@pytest.mark.parametrize("exc_type", [Boom, KeyboardInterrupt])
def test_exception_in_progress_cancels_and_is_reraised(images, exc_type, capfd):
    calls = []
    raised = exc_type("stop here")

    def progress(stage, done, total):
        calls.append(stage)
        raise raised

    with pytest.raises(exc_type) as e:
        topoloc.Map.build_from_images(images[:6], backend="vlad-orb", progress=progress)
    assert e.value is raised
    assert len(calls) == 1  # the build stopped at the first report
    assert "in progress" in "".join(
        traceback.format_tb(e.value.__traceback__)
    )  # the callback's frame
    assert "Exception ignored" not in capfd.readouterr().err  # nothing swallowed by ctypes


def test_exception_in_progress_of_a_file_build(tmp_path, images):
    for i, img in enumerate(images[:3]):
        write_pgm(tmp_path / f"{i}.pgm", img)

    def progress(stage, done, total):
        raise ZeroDivisionError("from the callback")

    with pytest.raises(ZeroDivisionError, match="from the callback"):
        topoloc.Map.build_from_image_files(tmp_path, backend="vlad-orb", progress=progress)
    # The next build is unaffected.
    with topoloc.Map.build_from_image_files(
        tmp_path, backend="vlad-orb", progress=lambda *a: True
    ) as m:
        assert m.place_count == 3


def test_progress_must_be_callable(images):
    with pytest.raises(TypeError, match="progress"):
        topoloc.Map.build_from_images(images[:3], backend="vlad-orb", progress=42)


# ---------------------------------------------------------------------------------------------
# Save / load keep the describer
# ---------------------------------------------------------------------------------------------


def test_save_and_load_keep_the_describer(vlad_map, images, tmp_path):
    path = tmp_path / "images.topomap"
    vlad_map.save(path)
    queries = [revisit(img, 300 + p) for p, img in enumerate(images)]
    with topoloc.Localizer(vlad_map, mode="single_frame") as loc:
        before = [loc.process(image=q, timestamp=0.0) for q in queries]
    for loaded in (
        topoloc.Map.load(path, expected_kind="vlad-orb"),
        topoloc.Map.from_bytes(path.read_bytes()),
    ):
        with loaded:
            assert loaded.descriptor_model == vlad_map.descriptor_model
            np.testing.assert_array_equal(loaded.view_descriptors(), vlad_map.view_descriptors())
            with topoloc.Localizer(loaded, mode="single_frame", image_backend="vlad-orb") as loc:
                after = [loc.process(image=q, timestamp=0.0) for q in queries]
        assert after == before


# ---------------------------------------------------------------------------------------------
# Maps from image files
# ---------------------------------------------------------------------------------------------


def test_build_from_a_folder_and_a_list_of_files(tmp_path, images):
    folder = tmp_path / "run"
    folder.mkdir()
    for i, img in enumerate(images[:6]):
        write_pgm(folder / f"img{5 - i:02d}.pgm", img)  # names sort in reverse order of images
    (folder / "notes.txt").write_text("not an image")
    (folder / "sub.png").mkdir()  # a folder, not an image
    names = [f"img{k:02d}.pgm" for k in range(6)]

    with topoloc.Map.build_from_image_files(folder, backend="vlad-orb") as m:
        assert m.place_count == 6
        assert [Path(m.view_image(v)).name for v in range(6)] == names
        assert [m.view_info(v).keyframe_id for v in range(6)] == list(range(6))
        from_folder = m.view_descriptors()
    files = [str(folder / n) for n in names]
    with topoloc.Map.build_from_image_files(files, backend="vlad-orb") as m:
        assert [m.view_image(v) for v in range(6)] == files
        np.testing.assert_array_equal(m.view_descriptors(), from_folder)
    # The same pixels in memory (files sorted by name = images reversed) give the same map.
    with topoloc.Map.build_from_images(images[:6][::-1], backend="vlad-orb") as m:
        np.testing.assert_array_equal(m.view_descriptors(), from_folder)


def test_colour_files_and_mixed_sizes(tmp_path, images):
    write_ppm(tmp_path / "a.ppm", colour(images[0], 0))
    write_pgm(tmp_path / "b.pgm", place_image(5, w=200, h=150))
    write_ppm(tmp_path / "c.ppm", colour(images[2], 2))
    with topoloc.Map.build_from_image_files(tmp_path, backend="vlad-orb") as m, topoloc.Localizer(
        m, mode="single_frame"
    ) as loc:
        assert m.place_count == 3
        # A PPM is RGB: the same pixels from memory find their file's place.
        assert loc.process(image=colour(images[2], 2), timestamp=0.0).place == 2


def test_file_build_errors(tmp_path, images):
    write_pgm(tmp_path / "a.pgm", images[0])
    with pytest.raises(topoloc.InvalidImageError, match=r"missing\.png"):
        topoloc.Map.build_from_image_files(
            [tmp_path / "a.pgm", tmp_path / "missing.png"], backend="vlad-orb"
        )
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(topoloc.InvalidImageError, match=r"broken\.png"):
        topoloc.Map.build_from_image_files(tmp_path, backend="vlad-orb")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(topoloc.InvalidArgumentError, match="no image files"):
        topoloc.Map.build_from_image_files(empty, backend="vlad-orb")
    with pytest.raises(topoloc.InvalidArgumentError, match="not a folder"):
        topoloc.Map.build_from_image_files(str(tmp_path / "a.pgm"), backend="vlad-orb")
    with pytest.raises(topoloc.InvalidArgumentError, match="at least 2 images"):
        topoloc.Map.build_from_image_files([tmp_path / "a.pgm"], backend="vlad-orb")


def test_build_argument_errors(images):
    with pytest.raises(topoloc.InvalidArgumentError, match="at least 2 images"):
        topoloc.Map.build_from_images(images[:1], backend="vlad-orb")
    with pytest.raises(topoloc.InvalidArgumentError, match="at least 2 images"):
        topoloc.Map.build_from_images([], backend="vlad-orb")
    with pytest.raises(topoloc.InvalidArgumentError, match="views_per_place"):
        topoloc.Map.build_from_images(images[:4], backend="vlad-orb", views_per_place=0)
    for backend in ("none", "auto", "cuda", topoloc._lib.BACKEND_NONE):
        with pytest.raises(topoloc.InvalidArgumentError, match="backend"):
            topoloc.Map.build_from_images(images[:4], backend=backend)
    with pytest.raises(topoloc.InvalidImageError, match=r"images\[1\]"):
        topoloc.Map.build_from_images([images[0], images[1][:, :, None, None]], backend="vlad-orb")
    with pytest.raises(TypeError, match=r"images\[2\].*float32"):
        topoloc.Map.build_from_images(
            [images[0], images[1], images[2].astype(np.float32)], backend="vlad-orb"
        )
    with pytest.raises(topoloc.InvalidImageError, match="8192"):  # checked by the library
        topoloc.Map.build_from_images(
            [images[0], np.zeros((9000, 10), np.uint8)], backend="vlad-orb"
        )
    with pytest.raises(topoloc.InvalidImageError, match="pixel_format"):
        topoloc.Map.build_from_images(images[:3], backend="vlad-orb", pixel_format="rgb")


# ---------------------------------------------------------------------------------------------
# Bad images: typed errors, state unchanged
# ---------------------------------------------------------------------------------------------

BAD_IMAGES = [
    # (name, image factory, pixel_format, expected exception); checked in Python or by the library
    ("float", lambda g: g.astype(np.float32), None, TypeError),
    ("int16", lambda g: g.astype(np.int16), None, TypeError),
    ("bool", lambda g: g > 128, None, TypeError),
    ("list", lambda g: g[:4, :4].tolist(), None, TypeError),
    ("path", lambda g: "frame.png", None, TypeError),
    ("1-D", lambda g: g.ravel(), None, topoloc.InvalidImageError),
    ("0-D", lambda g: np.uint8(7), None, topoloc.InvalidImageError),
    ("2 channels", lambda g: np.stack([g, g], -1), None, topoloc.InvalidImageError),
    ("4-D", lambda g: g[None, :, :, None], None, topoloc.InvalidImageError),
    ("zero width", lambda g: g[:, :0], None, topoloc.InvalidImageError),
    ("zero height", lambda g: g[:0], None, topoloc.InvalidImageError),
    ("format of other channels", lambda g: g, "rgb", topoloc.InvalidImageError),
    ("unknown format", lambda g: np.stack([g] * 3, -1), "yuv", topoloc.InvalidImageError),
    ("constant", lambda g: np.full_like(g, 90), None, topoloc.UninformativeImageError),
    (
        "black RGB",
        lambda g: np.zeros((*g.shape, 3), np.uint8),
        None,
        topoloc.UninformativeImageError,
    ),
    ("1x1", lambda g: g[:1, :1], None, topoloc.UninformativeImageError),
    ("10000x10000", lambda g: np.zeros((10000, 10000), np.uint8), None, topoloc.InvalidImageError),
    ("8193 wide", lambda g: np.tile(g[:2], (1, 26))[:, :8193], None, topoloc.InvalidImageError),
]


@pytest.mark.parametrize("name,make,fmt,expected", BAD_IMAGES, ids=[c[0] for c in BAD_IMAGES])
def test_bad_image_raises(vlad_map, images, name, make, fmt, expected):
    with topoloc.Localizer(vlad_map) as loc:
        with pytest.raises(expected) as e:
            loc.process(image=make(images[0]), pixel_format=fmt, timestamp=0.0)
        if isinstance(e.value, topoloc.TopolocError):
            assert e.value.message


def test_bad_images_leave_the_localizer_unchanged(vlad_map, images):
    with topoloc.Localizer(vlad_map) as loc, topoloc.Localizer(vlad_map) as twin:
        first = loc.process(image=images[0], timestamp=0.0)
        assert twin.process(image=images[0], timestamp=0.0) == first
        for t, (_name, make, fmt, expected) in enumerate(BAD_IMAGES):
            with pytest.raises(expected):
                loc.process(image=make(images[0]), pixel_format=fmt, timestamp=1.0 + t)
        a = loc.process(image=images[1], timestamp=50.0)
        b = twin.process(image=images[1], timestamp=50.0)
        assert a == b
        assert a.frame_index == first.frame_index + 1


def test_frame_argument_errors(vlad_map, images):
    with topoloc.Localizer(vlad_map) as loc:
        with pytest.raises(TypeError, match="descriptor or an image"):
            loc.process(timestamp=0.0)
        with pytest.raises(TypeError, match="not both"):
            loc.process(vlad_map.view_descriptor(0), 0.0, image=images[0])
        with pytest.raises(TypeError, match="timestamp"):
            loc.process(image=images[0])
        with pytest.raises(TypeError, match="pixel_format"):
            loc.process(vlad_map.view_descriptor(0), 0.0, pixel_format="rgb")
        assert loc.process(image=images[0], timestamp=0.0).frame_index == 0


def test_errors_of_image_frames_keep_the_filter_contract(vlad_map, images):
    with topoloc.Localizer(vlad_map) as loc:
        loc.process(image=images[0], timestamp=5.0)
        with pytest.raises(topoloc.TimestampError):
            loc.process(image=images[1], timestamp=4.0)
        with pytest.raises(topoloc.InvalidArgumentError):
            loc.process(image=images[1], timestamp=6.0, odometry=np.full((4, 4), 2.0))
        assert loc.process(image=images[1], timestamp=6.0, odometry=np.eye(4)).frame_index == 1


# ---------------------------------------------------------------------------------------------
# Strided and non-contiguous arrays
# ---------------------------------------------------------------------------------------------


def test_arrays_with_contiguous_rows_are_read_in_place():
    big = place_image(77, w=400, h=300)
    crop = big[30:270, 40:360]
    c_image, keep = _convert._image(crop, None, "image")
    assert np.shares_memory(keep, big)  # no copy
    assert c_image.stride == 400 and (c_image.width, c_image.height) == (320, 240)
    assert c_image.data_len == 400 * 239 + 320
    rgb = np.zeros((300, 400, 4), np.uint8)[10:20, 5:9, :3]  # crop of the colour channels of RGBA
    c_image, keep = _convert._image(rgb, "bgr", "image")
    assert not np.shares_memory(keep, rgb)  # pixels are 4 bytes apart: copied
    c_image, keep = _convert._image(np.zeros((300, 400, 3), np.uint8)[10:20, 5:9], "bgr", "image")
    assert c_image.stride == 1200 and c_image.format == topoloc._lib.PIXEL_BGR8
    for strided in (big[:, ::2], big[::-1], np.asfortranarray(big), big.T):
        c_image, keep = _convert._image(strided, None, "image")
        assert keep.flags.c_contiguous and not np.shares_memory(keep, big)
        assert c_image.stride == strided.shape[1]
    one_row = big[5:6, :]
    c_image, _ = _convert._image(one_row, None, "image")
    assert c_image.stride == 400 and c_image.data_len == 400


def test_non_contiguous_arrays_give_the_answers_of_contiguous_copies(vlad_map, images):
    q = revisit(images[6], 1)
    padded = np.zeros((H + 40, W + 60), np.uint8)
    padded[20 : 20 + H, 30 : 30 + W] = q
    doubled = np.repeat(q, 2, axis=1)  # every column twice
    c = colour(q, 1)
    cases = [
        padded[20 : 20 + H, 30 : 30 + W],  # crop: row stride 380, read in place
        doubled[:, ::2],  # column step: copied
        np.asfortranarray(q),  # column-major: copied
        q[::-1][::-1],  # negative strides twice: positive again
        np.ascontiguousarray(q[::-1])[::-1],  # negative row stride: copied
        np.lib.stride_tricks.as_strided(padded[20:, 30:], shape=q.shape, strides=padded.strides),
    ]
    colour_cases = [
        np.ascontiguousarray(np.moveaxis(np.moveaxis(c, 2, 0), 0, 2)),  # contiguous reference
        np.moveaxis(np.ascontiguousarray(np.moveaxis(c, 2, 0)), 0, 2),  # planar: copied
        np.concatenate([c, c], axis=1)[:, W:],  # crop of a wider image
    ]
    with topoloc.Localizer(vlad_map, mode="single_frame") as loc:
        expected = loc.process(image=np.ascontiguousarray(q), timestamp=0.0)
        assert expected.place == 6
        for i, arr in enumerate(cases):
            np.testing.assert_array_equal(arr, q)
            assert answer(loc.process(image=arr, timestamp=0.0)) == answer(expected), i
        expected_colour = loc.process(image=np.ascontiguousarray(c), timestamp=0.0)
        for i, arr in enumerate(colour_cases):
            np.testing.assert_array_equal(arr, c)
            assert answer(loc.process(image=arr, timestamp=0.0)) == answer(expected_colour), i
    # Building from crops and from copies gives the same map.
    crops = []
    for img in images[:5]:
        p = np.zeros((H + 2, W + 7), np.uint8)
        p[1 : 1 + H, 4 : 4 + W] = img
        crops.append(p[1 : 1 + H, 4 : 4 + W])
    with topoloc.Map.build_from_images(
        crops, backend="vlad-orb"
    ) as a, topoloc.Map.build_from_images(
        [np.ascontiguousarray(x) for x in crops], backend="vlad-orb"
    ) as b:
        np.testing.assert_array_equal(a.view_descriptors(), b.view_descriptors())


def test_read_only_arrays_are_accepted(vlad_map, images):
    q = images[4].copy()
    q.flags.writeable = False
    with topoloc.Localizer(vlad_map, mode="single_frame") as loc:
        assert loc.process(image=q, timestamp=0.0).place == 4


# ---------------------------------------------------------------------------------------------
# Describer selection: image_backend
# ---------------------------------------------------------------------------------------------


def test_geometric_verification(vlad_map, images, corridor):
    defaults = topoloc.localizer_options_default()
    assert defaults["verify_candidates"] == 0 and defaults["verify_views_per_candidate"] == 2
    with topoloc.Localizer(vlad_map, mode="single_frame") as plain:
        r = plain.process(image=revisit(images[5], 305), timestamp=0.0)
        assert r.place == 5 and not r.verified and r.inliers == 0
    with topoloc.Localizer(vlad_map, mode="single_frame", verify_candidates=3) as loc:
        assert loc.options["verify_candidates"] == 3
        r = loc.process(image=revisit(images[5], 305), timestamp=0.0)
        assert r.place == 5 and r.verified and r.inliers >= 20, r
        # A descriptor frame cannot be verified; the failed frame changes nothing.
        with pytest.raises(topoloc.InvalidImageError, match="verification"):
            loc.process(vlad_map.view_descriptor(2), timestamp=1.0)
        assert loc.process(image=images[2], timestamp=2.0).frame_index == 1
    # Maps built from descriptors store no keypoints.
    with pytest.raises(topoloc.InvalidOptionError, match="keypoints"):
        topoloc.Localizer(corridor.map, verify_candidates=3)
    with pytest.raises(topoloc.InvalidOptionError, match="views_per_candidate"):
        topoloc.Localizer(vlad_map, verify_candidates=3, verify_views_per_candidate=0)


def test_image_backend_none_refuses_image_frames(vlad_map, images):
    with topoloc.Localizer(vlad_map, image_backend="none") as loc:
        assert loc.options["image_backend"] == "none"
        with pytest.raises(topoloc.NoDescriberError):
            loc.process(image=images[0], timestamp=0.0)
        # Descriptor frames still work, and the failed frame changed nothing.
        r = loc.process(vlad_map.view_descriptor(3), 0.0)
        assert r.place == 3 and r.frame_index == 0


def test_maps_without_describer(corridor, images):
    with topoloc.Localizer(corridor.map) as loc:  # "auto": no describer to load
        with pytest.raises(topoloc.NoDescriberError):
            loc.process(image=images[0], timestamp=0.0)
        assert loc.process(corridor.query(2), 0.0).frame_index == 0
    for backend in ("vlad-orb", "vlad-sift", "onnx"):
        with pytest.raises(topoloc.NoDescriberError):
            topoloc.Localizer(corridor.map, image_backend=backend)
    topoloc.Localizer(corridor.map, image_backend="none").close()


def test_onnx_backend_on_a_vlad_map_is_a_mismatch(vlad_map):
    with pytest.raises(topoloc.DescriptorMismatchError, match="onnx"):
        topoloc.Localizer(vlad_map, image_backend="onnx")
    loc = topoloc.Localizer(vlad_map, image_backend="vlad-orb")
    assert loc.options["image_backend"] == "vlad-orb"
    loc.close()


def test_vlad_sift_backend_on_a_vlad_orb_map_is_a_mismatch(vlad_map):
    with pytest.raises(topoloc.DescriptorMismatchError):
        topoloc.Localizer(vlad_map, image_backend="vlad-sift")


def test_image_backend_option_values(vlad_map):
    with pytest.raises(topoloc.InvalidOptionError, match="image_backend"):
        topoloc.Localizer(vlad_map, image_backend="cuda")
    with pytest.raises(topoloc.InvalidOptionError, match="image_backend"):
        topoloc.Localizer(vlad_map, image_backend=-1)
    with pytest.raises(topoloc.TopolocError):  # unknown code: refused by the library
        topoloc.Localizer(vlad_map, image_backend=99)
    with topoloc.Localizer(vlad_map, image_backend=topoloc._lib.BACKEND_VLAD_ORB) as loc:
        assert loc.options["image_backend"] == "vlad-orb"
    # ONNX paths are recorded (and unused by a VLAD map).
    with topoloc.Localizer(
        vlad_map, onnx_model_path=Path("/nonexistent/m.onnx"), onnx_runtime_path="/x/ort.so"
    ) as loc:
        assert loc.options["onnx_model_path"] == "/nonexistent/m.onnx"
        assert loc.options["onnx_runtime_path"] == "/x/ort.so"
    d = topoloc.localizer_options_default()
    assert (d["image_backend"], d["onnx_model_path"], d["onnx_runtime_path"]) == (
        "auto",
        None,
        None,
    )


def test_localizer_outlives_the_map_for_image_frames(images):
    m = topoloc.Map.build_from_images(images[:5], backend="vlad-orb")
    loc = topoloc.Localizer(m, mode="single_frame")
    m.close()
    assert loc.process(image=images[3], timestamp=0.0).place == 3
    loc.close()


# ---------------------------------------------------------------------------------------------
# Keypoints, their scene points and pose fixes (ABI 1.6)
# ---------------------------------------------------------------------------------------------

# A pinhole camera for the place images; the map frame is each view's optical frame.
FX = FY = 400.0
CX, CY = (W - 1) / 2, (H - 1) / 2
CAMERA = dict(camera_fx=FX, camera_fy=FY, camera_cx=CX, camera_cy=CY)
NEAR, FAR = 1.0, 4.0  # depths of the scene left and right of the principal point, metres
SHIFT = 2  # pixels the query's content moves left


def scene_points(m: topoloc.Map) -> List[np.ndarray]:
    """Per view, the (N, 3) scene point of each keypoint: keypoints with x < CX at depth NEAR,
    the others at FAR, back-projected through the camera."""
    out = []
    for v in range(m.view_count):
        uv = m.view_keypoints(v).astype(np.float64)
        d = np.where(uv[:, 0] < CX, NEAR, FAR)
        out.append(np.stack([(uv[:, 0] - CX) / FX * d, (uv[:, 1] - CY) / FY * d, d], axis=1))
    return out


def shifted_left(img: np.ndarray, seed: int, px: int = SHIFT) -> np.ndarray:
    """``img`` with its content ``px`` pixels to the left (``query[:, x] = img[:, x + px]``,
    the last column repeated), 10% brighter, with noise of at most 3 grey levels."""
    rng = np.random.default_rng(seed)
    shifted = np.concatenate([img[:, px:], np.repeat(img[:, -1:], px, axis=1)], axis=1).astype(
        np.int32
    )
    return np.clip(shifted * 11 // 10 + rng.integers(-3, 4, size=img.shape), 0, 255).astype(
        np.uint8
    )


def project(world_T_camera: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of the map-frame points ``xyz`` seen by the camera at ``world_T_camera``."""
    camera_T_world = np.linalg.inv(world_T_camera)
    p = xyz @ camera_T_world[:3, :3].T + camera_T_world[:3, 3]
    return np.stack([FX * p[:, 0] / p[:, 2] + CX, FY * p[:, 1] / p[:, 2] + CY], axis=1)


@pytest.fixture(scope="module")
def points_map(vlad_map):
    m = vlad_map.with_keypoint_points(np.concatenate(scene_points(vlad_map)))
    yield m
    m.close()


def test_view_keypoints_add_up_to_the_keypoint_total(vlad_map, corridor):
    counts = []
    for v in range(vlad_map.view_count):
        kp = vlad_map.view_keypoints(v)
        assert kp.dtype == np.float32 and kp.ndim == 2 and kp.shape[1] == 2
        assert ((kp >= 0) & (kp <= [W - 1, H - 1])).all()  # pixel positions in the image
        counts.append(len(kp))
    assert min(counts) > 100  # beyond the first buffer: read in two calls
    assert vlad_map.keypoint_total == sum(counts)
    np.testing.assert_array_equal(vlad_map.view_keypoints(3), vlad_map.view_keypoints(3))
    # The C contract: a short buffer is refused, and the count written anyway.
    count = ctypes.c_size_t(0)
    status = _lib.lib.topoloc_map_view_keypoints(vlad_map._h, 3, None, 0, ctypes.byref(count))
    assert status == topoloc.BufferTooSmallError.STATUS and count.value == counts[3]
    for view in (PLACES, -1):
        with pytest.raises(topoloc.UnknownViewError):
            vlad_map.view_keypoints(view)
    # A map built from descriptors stores no keypoints.
    assert corridor.map.keypoint_total == 0
    with pytest.raises(topoloc.InvalidArgumentError, match="no keypoints") as info:
        corridor.map.view_keypoints(0)
    assert info.value.status == 2
    with pytest.raises(topoloc.UnknownViewError):  # the view is checked first
        corridor.map.view_keypoints(corridor.map.view_count)


def test_with_keypoint_points_makes_a_new_map(vlad_map, points_map, images):
    m = points_map
    for name in (
        "place_count",
        "view_count",
        "edge_count",
        "dim",
        "descriptor_kind",
        "keypoint_total",
    ):
        assert getattr(m, name) == getattr(vlad_map, name), name
    np.testing.assert_array_equal(m.view_descriptors(), vlad_map.view_descriptors())
    for v in range(m.view_count):
        np.testing.assert_array_equal(m.view_keypoints(v), vlad_map.view_keypoints(v))
    # Rows of NaN (unknown points) are accepted, from any array-like; the copy outlives the
    # map it was made from.
    with topoloc.Map.build_from_images(images[:2], backend="vlad-orb") as small:
        xyz = np.full((small.keypoint_total, 3), np.nan)
        xyz[::3] = [0.0, 0.0, 2.0]
        copy = small.with_keypoint_points(xyz.tolist())
    with copy, topoloc.Localizer(copy, mode="single_frame", verify_candidates=2, **CAMERA) as loc:
        assert copy.keypoint_total == len(xyz)
        assert loc.process(image=images[1], timestamp=0.0).place == 1


def test_with_keypoint_points_checks_the_array(vlad_map, corridor, images, monkeypatch):
    total = vlad_map.keypoint_total
    xyz = np.concatenate(scene_points(vlad_map))

    def not_called(*args):
        raise AssertionError("topoloc_map_with_keypoint_points was called")

    monkeypatch.setattr(_lib.lib, "topoloc_map_with_keypoint_points", not_called)
    for bad in (xyz[:, :2], xyz.reshape(-1), xyz[:, :, None], xyz.T, np.zeros((total, 4)), 1.0):
        with pytest.raises(topoloc.InvalidArgumentError, match=r"\(N, 3\)"):
            vlad_map.with_keypoint_points(bad)
    for dtype in (str, complex, object):
        with pytest.raises(TypeError, match="dtype"):
            vlad_map.with_keypoint_points(xyz.astype(dtype))
    monkeypatch.undo()
    # Checked by the library: the number of rows, partly unknown or infinite points, a map
    # without keypoints.
    for rows in (xyz[:-1], np.concatenate([xyz, xyz[:1]]), xyz[:0]):
        with pytest.raises(
            topoloc.InvalidArgumentError, match=f"keypoints need {3 * total}"
        ) as info:
            vlad_map.with_keypoint_points(rows)
        assert info.value.status == 2
    partly = xyz.copy()
    partly[7, 2] = np.nan
    infinite = xyz.copy()
    infinite[4] = np.inf
    for rows in (partly, infinite):
        with pytest.raises(topoloc.InvalidArgumentError):
            vlad_map.with_keypoint_points(rows)
    with pytest.raises(topoloc.InvalidArgumentError, match="no keypoints"):
        corridor.map.with_keypoint_points(np.zeros((0, 3)))
    # The map is unchanged and still works.
    assert vlad_map.keypoint_total == total
    with topoloc.Localizer(vlad_map, mode="single_frame", verify_candidates=3) as loc:
        r = loc.process(image=revisit(images[5], 305), timestamp=0.0)
        assert r.place == 5 and r.verified and r.inliers >= 20 and r.pose_fix is None


def test_pose_fix_places_the_camera(points_map, images):
    with topoloc.Localizer(
        points_map, mode="single_frame", verify_candidates=3, pose_min_inliers=12, **CAMERA
    ) as loc, topoloc.Localizer(points_map, mode="single_frame", verify_candidates=3) as plain:
        o = loc.options
        assert (o["camera_fx"], o["camera_fy"], o["camera_cx"], o["camera_cy"]) == (FX, FY, CX, CY)
        assert o["pose_min_inliers"] == 12 and o["verify_candidates"] == 3
        scene = scene_points(points_map)
        for p in (0, 5, 9):
            query = shifted_left(images[p], 500 + p)
            r = loc.process(image=query, timestamp=0.0)
            fix = r.pose_fix
            assert r.place == p and r.verified, r
            assert fix is not None, f"no pose fix for place {p}: {r.inliers} verification inliers"
            assert isinstance(fix, topoloc.PoseFix) and fix.view == p and fix.inliers >= 12, fix
            pose = fix.world_T_camera
            assert pose.dtype == np.float64 and pose.shape == (4, 4)
            np.testing.assert_allclose(pose[3], [0, 0, 0, 1])
            np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-9)
            # The stored keypoints' scene points project where the query sees them: SHIFT
            # pixels to the left. Without the fix (the identity pose) they would be SHIFT off.
            expected = points_map.view_keypoints(fix.view) - [SHIFT, 0]
            error = np.linalg.norm(project(pose, scene[fix.view]) - expected, axis=1)
            assert np.median(error) < 1.5, (p, np.median(error), fix)
            assert (
                np.median(np.linalg.norm(project(np.eye(4), scene[fix.view]) - expected, axis=1))
                > 1.5
            )
            # The same shift at 1 m and at 4 m is a pure turn, about the y axis, by
            # atan(SHIFT / FX).
            assert np.linalg.norm(pose[:3, 3]) < 0.02, pose
            assert np.arctan2(pose[0, 2], pose[2, 2]) == pytest.approx(
                np.arctan(SHIFT / FX), abs=5e-4
            )
            # The same frame again gives the same answer; without a camera, no pose fix.
            again = loc.process(image=query, timestamp=0.0)
            assert again.pose_fix == fix and answer(again) == answer(r)
            without = plain.process(image=query, timestamp=0.0)
            assert without.verified and without.inliers == r.inliers and without.pose_fix is None


def test_pose_fix_options(vlad_map, points_map, images):
    d = topoloc.localizer_options_default()
    assert (d["camera_fx"], d["camera_fy"], d["camera_cx"], d["camera_cy"]) == (0.0, 0.0, 0.0, 0.0)
    assert d["pose_min_inliers"] == 30
    bad = [
        dict(CAMERA, camera_fx=-400.0),
        dict(CAMERA, camera_fy=0.0),
        dict(CAMERA, camera_cx=float("nan")),
        dict(CAMERA, camera_fy=float("inf")),
        dict(CAMERA, pose_min_inliers=5),
        dict(CAMERA, pose_min_inliers=-1),
        dict(pose_min_inliers=10001),
    ]
    for kwargs in bad:
        with pytest.raises(topoloc.InvalidOptionError) as info:
            topoloc.Localizer(points_map, verify_candidates=3, **kwargs)
        assert info.value.status == 204 and info.value.message, kwargs
    with pytest.raises(topoloc.InvalidOptionError, match="fx"):
        topoloc.Localizer(points_map, verify_candidates=3, **dict(CAMERA, camera_fx=-400.0))
    # Pose fixes come from verified views, against scene points.
    with pytest.raises(topoloc.InvalidOptionError, match="candidates"):
        topoloc.Localizer(points_map, **CAMERA)
    with pytest.raises(topoloc.InvalidOptionError, match="scene points") as info:
        topoloc.Localizer(vlad_map, verify_candidates=3, **CAMERA)
    assert info.value.status == 204
    # Too few inliers for the threshold: verified, but no pose fix.
    with topoloc.Localizer(
        points_map, mode="single_frame", verify_candidates=3, pose_min_inliers=10000, **CAMERA
    ) as loc:
        r = loc.process(image=shifted_left(images[4], 4), timestamp=0.0)
        assert r.place == 4 and r.verified and r.inliers >= 12 and r.pose_fix is None


# ---------------------------------------------------------------------------------------------
# ONNX (when the model is installed)
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def onnx_map(images):
    require_models(ONNX_MODEL)
    try:
        m = topoloc.Map.build_from_images(images[:6], backend="onnx", threads=2)
    except topoloc.BackendUnavailableError as e:
        skip_or_fail(f"ONNX Runtime unavailable: {e}")
    yield m
    m.close()


def test_onnx_map_localizes_revisits_and_survives_save(onnx_map, images, tmp_path):
    assert onnx_map.descriptor_kind == "onnx-mlf"
    assert onnx_map.place_count == 6 and onnx_map.dim == 5
    queries = [revisit(img, 400 + p) for p, img in enumerate(images[:6])]
    with topoloc.Localizer(onnx_map, mode="single_frame") as loc:
        before = [loc.process(image=q, timestamp=0.0) for q in queries]
    assert sum(r.place == p for p, r in enumerate(before)) >= 5
    path = tmp_path / "onnx.topomap"
    onnx_map.save(path)
    with topoloc.Map.load(path, expected_kind="onnx-mlf") as m, topoloc.Localizer(
        m, mode="single_frame", image_backend="onnx", onnx_model_path=ONNX_MODEL
    ) as loc:
        assert [loc.process(image=q, timestamp=0.0) for q in queries] == before


def test_onnx_colour_frames(onnx_map, images):
    with topoloc.Localizer(onnx_map, mode="single_frame") as loc:
        rgb = np.repeat(images[2][:, :, None], 3, axis=2)
        a = loc.process(image=rgb, timestamp=0.0)
        assert a.place == 2
        b = loc.process(
            image=np.ascontiguousarray(rgb[:, :, ::-1]), pixel_format="bgr", timestamp=0.0
        )
        assert answer(b) == answer(a)


def test_onnx_describer_mismatches_and_missing_files(onnx_map, tmp_path, images):
    with pytest.raises(topoloc.DescriptorMismatchError):
        topoloc.Localizer(onnx_map, image_backend="vlad-orb")
    missing = tmp_path / "missing.onnx"
    with pytest.raises(topoloc.BackendUnavailableError, match=r"missing\.onnx"):
        topoloc.Map.build_from_images(images[:3], backend="onnx", onnx_model_path=missing)
    with pytest.raises((topoloc.BackendUnavailableError, topoloc.DescriptorMismatchError)):
        topoloc.Localizer(onnx_map, onnx_model_path=missing)
    corrupt = tmp_path / "corrupt.onnx"
    corrupt.write_bytes(b"this is not an ONNX model")
    with pytest.raises(topoloc.ModelError, match=r"corrupt\.onnx"):
        topoloc.Map.build_from_images(images[:3], backend="onnx", onnx_model_path=corrupt)
    with pytest.raises((topoloc.DescriptorMismatchError, topoloc.ModelError)):
        topoloc.Localizer(onnx_map, onnx_model_path=corrupt)
    # Descriptor-only use of an ONNX map never loads the runtime.
    with topoloc.Localizer(
        onnx_map, image_backend="none", onnx_runtime_path=tmp_path / "none.so"
    ) as loc:
        assert loc.process(onnx_map.view_descriptor(1), 0.0).place == 1


def test_onnx_build_from_files_with_progress(tmp_path, images):
    require_models(ONNX_MODEL)
    for i, img in enumerate(images[:4]):
        write_ppm(tmp_path / f"{i}.ppm", colour(img, i))
    seen = []
    with topoloc.Map.build_from_image_files(
        tmp_path, backend="onnx", dim=3, progress=lambda *a: seen.append(a)
    ) as m:
        assert (m.place_count, m.dim) == (4, 3)
    assert ("describing", 4, 4) in seen and seen[-1] == ("fitting", 1, 1)


def test_the_off_map_flag_reads_verification_inliers_when_told(vlad_map, images):
    """ABI 1.9: with a threshold (ORB maps default to 0: appearance decides), frames of scenes
    the map has never seen are flagged within 10 frames, and returning clears the flag; bad
    values are refused."""
    d = topoloc.localizer_options_default()
    assert d["verify_off_map_inliers"] < 0 and d["verify_off_map_inlier_scale"] == 4.0
    home = images[3]
    elsewhere = [place_image(5000 + i) for i in range(15)]
    with topoloc.Localizer(vlad_map, verify_candidates=3, verify_off_map_inliers=30.0) as loc:
        assert loc.options["verify_off_map_inliers"] == 30.0
        stream = [home] * 10 + elsewhere + [home] * 10
        flags = [
            loc.process(image=image, timestamp=0.1 * i).off_map for i, image in enumerate(stream)
        ]
    assert not any(flags[:10]), flags
    assert all(flags[20:25]), flags
    assert not any(flags[28:]), flags
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.Localizer(vlad_map, verify_candidates=3, verify_off_map_inliers=float("nan"))
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.Localizer(vlad_map, verify_candidates=3, verify_off_map_inlier_scale=0.0)


def test_describer_describes_as_the_map_and_feeds_a_loop_detector(vlad_map, images):
    with topoloc.Describer(vlad_map) as describer:
        assert describer.dim == vlad_map.dim
        for i, img in enumerate(images):
            d = describer.describe(img)
            assert d.dtype == np.float32 and d.shape == (vlad_map.dim,)
            assert float(d @ vlad_map.view_descriptor(i)) > 0.9999  # the same image again
        # A revisit is nearest its own view.
        q = describer.describe(revisit(images[3], 7))
        sims = [float(q @ vlad_map.view_descriptor(i)) for i in range(len(images))]
        assert int(np.argmax(sims)) == 3
        with topoloc.LoopDetector(
            vlad_map.descriptor_kind, vlad_map.descriptor_model, vlad_map.dim
        ) as det:
            hint = det.add(1, 0.0, q)
            assert not hint.has_match and len(det) == 1
        with pytest.raises(topoloc.UninformativeImageError):
            describer.describe(np.full((H, W), 128, np.uint8))
        with pytest.raises(topoloc.InvalidImageError):
            describer.describe(np.zeros((0, W), np.uint8))
        with pytest.raises(TypeError):
            describer.describe(images[0].astype(np.float32))
    with pytest.raises(ValueError):
        describer.describe(images[0])


def test_describer_errors(vlad_map):
    with topoloc.MapBuilder("ext", "m", dim=4) as b:
        b.add_view(b.add_place(), [1, 0, 0, 0])
        plain = b.build()
    with pytest.raises(topoloc.NoDescriberError):
        topoloc.Describer(plain)
    with pytest.raises(topoloc.DescriptorMismatchError):
        topoloc.Describer(vlad_map, backend="onnx")
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.Describer(vlad_map, backend="none")
    with pytest.raises(topoloc.InvalidOptionError):
        topoloc.Describer(vlad_map, threads=0)
    with pytest.raises(TypeError):
        topoloc.Describer("not a map")
