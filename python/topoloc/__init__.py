"""topoloc: visual topological localization and loop-closure hints for SLAM.

Pure-Python ctypes bindings over the stable C ABI of ``libtopoloc`` (see ``include/topoloc.h``),
with numpy arrays in and out.

Quick start::

    import numpy as np
    import topoloc

    with topoloc.MapBuilder("netvlad", "pitts30k", dim=4) as b:
        p0 = b.add_place(position=[0, 0, 0])
        b.add_view(p0, [1, 0, 0, 0], keyframe_id=7)
        p1 = b.add_place(position=[2, 0, 0])
        b.add_view(p1, [0, 1, 0, 0])
        b.add_edge(p0, p1)
        m = b.build()

    with m, topoloc.Localizer(m, mode="filter") as loc:
        r = loc.process(np.array([0.1, 0.9, 0, 0]), timestamp=0.0)
        print(r.place, r.confidence, r.candidates)

A topological graph of places can be built from an occupancy voxel grid of your own mapping
stack (``topoloc.skeleton_graph(occupied, voxel_size, origin)``, ``occupied`` indexed
``[x, y, z]``): its places and edges can then be given to a :class:`MapBuilder` with their views.

Maps can also be built from camera images (``Map.build_from_images`` with uint8 numpy arrays,
``Map.build_from_image_files`` with files or a folder); such maps store their describer, and
a localizer on them accepts images: ``loc.process(image=frame, timestamp=t)``.

Pose fixes (ABI 1.6): such maps store keypoints per view (``Map.view_keypoints``); with their
scene points attached (``Map.with_keypoint_points``, from depth or SLAM map points) and the
camera intrinsics given to a :class:`Localizer` (``camera_fx`` ... ``camera_cy``, with
``verify_candidates``), a result may carry a :class:`PoseFix`, the camera's metric pose in the
map frame.

Loop closure (ABI 1.5): a :class:`LoopDetector` takes SLAM keyframes (global descriptor,
keypoints with binary descriptors, optional poses) and returns one gated :class:`LoopHint` per
keyframe, with the relative pose when camera intrinsics are given (:class:`Translation` says
whether its translation is metric, a direction, or none). Keyframe ids count keyframes, not
camera frames. A live run starts an empty detector; a later run closes loops against an
earlier one with ``LoopDetector.from_map(Map.load(saved))``, never with a map of its own
images (each keyframe would match itself: :attr:`Gate.SELF_MATCH`).

A :class:`Describer` (ABI 1.12) turns images into the global descriptors of a map built from
images, for a loop detector made for that map's descriptors
(``LoopDetector.for_descriptors_of(m)``). A :class:`KeyframeDescriber` (ABI 1.15) also extracts the
image's local features (XFeat by default, :class:`LocalFeatures`) in the same pass:
:meth:`LoopDetector.add_image` takes keyframes as images (and depth), and
:meth:`LoopDetector.candidates` lists the verified candidates (:class:`LoopCandidateCheck`).

Trajectory metrics (ABI 1.11): :func:`evaluate_trajectory` (TUM rows) and
:func:`evaluate_trajectory_files` (TUM, KITTI, EuRoC) give ATE, ARE, RPE and R_traj of an
estimate against ground truth, as ``evo_ape`` / ``evo_rpe`` compute them.

Logging (ABI 1.13): the library's records go to :mod:`logging` (loggers ``topoloc.*`` and
``onnxruntime``), from ``WARNING`` by default; :func:`set_log_level` asks for more
(``logging.INFO``: maps loaded and saved; ``logging.DEBUG``: loop decisions; :data:`TRACE`:
per frame). The library itself never prints.

Objects and threads: a :class:`Map` is immutable and may be shared by many threads; a
:class:`Localizer` (one camera), a :class:`LoopDetector` and a :class:`MapBuilder` are
single-threaded state. Every
object owning a C handle is a context manager, has ``close()``, and is released when garbage
collected. Failures raise subclasses of :class:`TopolocError` (see :mod:`topoloc._errors`).

The shared library is found through ``TOPOLOC_LIBRARY``, next to this package, in the
``target/release`` directory of a source checkout, or on the system (see :mod:`topoloc._lib`).
"""

from ._describer import Describer
from ._errors import (
    BackendUnavailableError,
    BufferTooSmallError,
    CancelledError,
    ConcurrentUseError,
    CorruptMapError,
    DescriptorMismatchError,
    DimensionMismatchError,
    EmptyMapError,
    InvalidArgumentError,
    InvalidImageError,
    InvalidMapError,
    InvalidOptionError,
    InvalidUTF8Error,
    MapIOError,
    ModelError,
    NoDescriberError,
    NonFiniteError,
    NotAMapError,
    NullArgumentError,
    PanicError,
    StructSizeError,
    TimestampError,
    TopolocError,
    TruncatedMapError,
    UninformativeImageError,
    UnknownPlaceError,
    UnknownViewError,
    UnsupportedVersionError,
    ZeroDescriptorError,
)
from ._keyframes import KeyframeDescriber, LocalFeatures, LoopCandidateCheck
from ._lib import (
    ABI_VERSION,
    MODE_FILTER,
    MODE_METRIC,
    MODE_SINGLE_FRAME,
    NODE_BRANCH,
    NODE_CORNER,
    NODE_END,
    NODE_INTERMEDIATE,
    AbiVersionError,
    LibraryNotFoundError,
    library_path,
)
from ._localizer import Candidate, Localizer, PoseFix, Result, localizer_options_default
from ._logging import TRACE, log_level, set_log_level
from ._loops import Gate, LoopCandidate, LoopDetector, LoopHint, Translation, loop_options_default
from ._map import Map, MapBuilder, ViewInfo, keyframe_options_default, map_from_keyframes
from ._skeleton import Graph, skeleton_graph, skeleton_options_default
from ._trajectory import (
    ErrorStats,
    TrajectoryReport,
    evaluate_trajectory,
    evaluate_trajectory_files,
)
from ._version import abi_version, abi_version_minor, status_name, status_str, version

#: Version of the loaded shared library (a wheel's own version: both are Cargo.toml's).
__version__: str = version()

__all__ = [
    # maps
    "Map",
    "MapBuilder",
    "map_from_keyframes",
    "keyframe_options_default",
    "ViewInfo",
    # skeleton graphs from occupancy grids
    "skeleton_graph",
    "skeleton_options_default",
    "Graph",
    "NODE_END",
    "NODE_CORNER",
    "NODE_BRANCH",
    "NODE_INTERMEDIATE",
    # localization
    "Localizer",
    "localizer_options_default",
    "Result",
    "Candidate",
    "PoseFix",
    "MODE_FILTER",
    "MODE_SINGLE_FRAME",
    "MODE_METRIC",
    # describers (ABI 1.12)
    "Describer",
    # loop closure (ABI 1.5)
    "LoopDetector",
    "loop_options_default",
    "LoopHint",
    "LoopCandidate",
    "LoopCandidateCheck",
    "KeyframeDescriber",
    "LocalFeatures",
    "Gate",
    "Translation",
    # trajectory metrics (ABI 1.11)
    "evaluate_trajectory",
    "evaluate_trajectory_files",
    "TrajectoryReport",
    "ErrorStats",
    # versions and library
    "version",
    # host logging (ABI 1.13)
    "set_log_level",
    "log_level",
    "TRACE",
    "abi_version",
    "abi_version_minor",
    "status_name",
    "status_str",
    "ABI_VERSION",
    "library_path",
    "LibraryNotFoundError",
    "AbiVersionError",
    # errors
    "TopolocError",
    "NullArgumentError",
    "InvalidArgumentError",
    "BufferTooSmallError",
    "StructSizeError",
    "InvalidUTF8Error",
    "MapIOError",
    "NotAMapError",
    "TruncatedMapError",
    "CorruptMapError",
    "UnsupportedVersionError",
    "DescriptorMismatchError",
    "EmptyMapError",
    "InvalidMapError",
    "UnknownPlaceError",
    "UnknownViewError",
    "DimensionMismatchError",
    "NonFiniteError",
    "ZeroDescriptorError",
    "TimestampError",
    "InvalidOptionError",
    "InvalidImageError",
    "UninformativeImageError",
    "BackendUnavailableError",
    "ModelError",
    "NoDescriberError",
    "CancelledError",
    "ConcurrentUseError",
    "PanicError",
]
