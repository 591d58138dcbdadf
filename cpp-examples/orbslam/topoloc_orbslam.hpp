/*
 * topoloc_orbslam.hpp: a drop-in replacement for the `KeyFrameDatabase` of ORB-SLAM2 and
 * ORB-SLAM3 over topoloc (header-only, C++17, OpenCV core).
 *
 * ORB-SLAM's database answers two questions with a DBoW2 inverted file: "which earlier keyframes
 * may close a loop with this one" (loop closing thread) and "which keyframes may this lost frame
 * be near" (tracking thread). `topoloc_orbslam::KeyFrameDatabase` answers both with topoloc:
 * every keyframe's image is described with the map's describer (`topoloc::Describer`), and the
 * keyframe (global descriptor, undistorted keypoints, ORB descriptors, the 3D points of its
 * matched map points in its camera frame, its pose) goes into a `topoloc::LoopDetector`, whose
 * gated hint of the keyframe (verified against the keypoints, consistent, checked against the
 * odometry) names the loop candidate and carries the relative pose; relocalization is the
 * detector's global-descriptor query.
 *
 * This file is original code written against the calls ORB-SLAM makes; it contains no
 * ORB-SLAM code. See README.md next to it for the integration lines.
 *
 * Errors: apart from the constructor, no member throws. Each call that fails (bad input, a
 * topoloc error, an accessor that throws) leaves the database unchanged, returns no candidates,
 * stores a message readable with `last_error()` on the calling thread, counts it in
 * `error_count()` and passes it to the logger, if one is set.
 *
 * Thread safety: every member locks one mutex, as ORB-SLAM's own database does, so the tracking
 * thread (relocalization) and the loop closing thread may call it concurrently. The logger is
 * called after the mutex is released, possibly from several threads at once.
 */
#ifndef TOPOLOC_ORBSLAM_HPP
#define TOPOLOC_ORBSLAM_HPP

#include "topoloc_opencv.hpp"

#include "../common/adapter_support.hpp"

#include <opencv2/core.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

namespace topoloc_orbslam {

/// A rigid transform, 16 doubles row-major `[R t; 0 0 0 1]` (the topoloc layout).
using Pose = topoloc::Pose;

/// Fisheye keypoints whose bearing has z at most this share of its length (87 degrees or
/// more off the axis) have no pinhole projection worth keeping.
inline constexpr double kMinBearingZ = 0.05;

/// Most keypoints topoloc takes from one keyframe (its `topoloc_loop_keyframe` bound).
inline constexpr std::size_t kMaxKeypoints = 5000;

/// Pinhole intrinsics of the undistorted keypoints (`mvKeysUn`), pixels: ORB-SLAM's `fx`,
/// `fy`, `cx`, `cy` (the `Camera.fx` ... entries of its settings file).
struct Intrinsics {
    double fx = 0.0; ///< Focal length x, pixels (> 0).
    double fy = 0.0; ///< Focal length y, pixels (> 0).
    double cx = 0.0; ///< Principal point x, pixels.
    double cy = 0.0; ///< Principal point y, pixels.
};

/// Behaviour of the adapter itself (the topoloc detector's options are `topoloc::LoopOptions`).
struct Settings {
    /// Most keyframes `DetectRelocalizationCandidates` returns, most similar first. Default 5.
    std::size_t relocalization_candidates = 5;
    /// A monocular map: its units drift and are not metres, so topoloc's odometry gate (bounds
    /// in metres) is turned off, and a hint's translation is in the matched keyframe's map
    /// units. Let `Sim3Solver` estimate the scale (do not seed `ComputeSim3` with scale 1).
    /// Default false (stereo, RGB-D, or with an IMU: metric).
    bool monocular = false;
    /// Keypoints of a keyframe given to topoloc (1..=`kMaxKeypoints`): those with a map point
    /// first, then the strongest (`cv::KeyPoint::response`). Matching two keyframes costs the
    /// product of their counts: ORB-SLAM's 2,000 per KITTI keyframe (about 10,000 during
    /// monocular initialisation) verified at 393 ms per keyframe inside ORB-SLAM3, where
    /// topoloc's own ORB default is 500 (BENCHMARKS.md). Default 500.
    std::size_t max_keypoints = 500;
    /// Receives every error message (see the top of this header); empty = none. Called without
    /// the database's mutex held, possibly from the tracking and the loop closing thread at once:
    /// it must be thread-safe and must not throw (an exception it throws is swallowed).
    topoloc_adapter::Logger logger;
};

/// topoloc's verdict on one keyframe: its `topoloc::LoopHint` (`accepted`: every topoloc gate
/// passed, a loop or merge closure; `gate`, `inliers`, `confidence`, `has_pose`, `scale_known`:
/// the translation is in the map's units, the matched keyframe had map points, else a unit
/// direction; `matched_T_query`: the query camera in the matched camera's frame, `Tmq = Tmw *
/// Twq` in ORB-SLAM notation, `X_matched = Tmq * X_query`; `covariance` of `matched_T_query`,
/// rotation then translation as g2o's SE3 tangent), with the keyframes resolved to the host's
/// pointers and the inverse pose. A plain value: it does not own the keyframes, which ORB-SLAM
/// may delete later.
template <typename KeyFrame> struct LoopMatch : topoloc::LoopHint {
    KeyFrame *query = nullptr;   ///< The keyframe the hint is about.
    KeyFrame *matched = nullptr; ///< The keyframe it matched; null once that one is erased or bad.
    /// The inverse of `matched_T_query`, `Tqm`, current-from-candidate: what ORB-SLAM2's
    /// `Sim3Solver` estimates as `gScm` (with scale 1) and its `ComputeSim3` composes with the
    /// candidate's `Tcw`. ORB-SLAM3 v1.0 takes no pose guess: it uses the candidates only.
    Pose query_T_matched{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
};

// ---------------------------------------------------------------------------------------------
// Conversions used by the accessors
// ---------------------------------------------------------------------------------------------

/// A pose from a 4x4 (or 3x4) single-channel CV_32F / CV_64F `cv::Mat` such as ORB-SLAM2's
/// `KeyFrame::GetPose()`; `std::nullopt` for an empty Mat (no pose). Throws
/// `std::invalid_argument` for any other shape or type (the adapter reports it as an error).
[[nodiscard]] inline std::optional<Pose> pose_from_mat(const cv::Mat &mat)
{
    if (mat.empty())
        return std::nullopt;
    const bool shape = mat.dims == 2 && mat.cols == 4 && (mat.rows == 4 || mat.rows == 3);
    if (!shape || (mat.type() != CV_32FC1 && mat.type() != CV_64FC1)) {
        throw std::invalid_argument("pose cv::Mat must be 4x4 or 3x4 CV_32F/CV_64F, got " +
                                    std::to_string(mat.rows) + "x" + std::to_string(mat.cols) +
                                    " of type " + std::to_string(mat.type()));
    }
    Pose pose{0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    for (int r = 0; r < mat.rows; ++r)
        for (int c = 0; c < 4; ++c)
            pose[static_cast<std::size_t>(4 * r + c)] =
                mat.type() == CV_32FC1 ? double(mat.at<float>(r, c)) : mat.at<double>(r, c);
    return pose;
}

/// A pose from any 4x4 matrix type with `m(row, col)`, e.g. ORB-SLAM3's
/// `Sophus::SE3f::matrix()` (an `Eigen::Matrix4f`).
template <typename Matrix> [[nodiscard]] Pose pose_from_matrix(const Matrix &m)
{
    Pose pose{};
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c)
            pose[static_cast<std::size_t>(4 * r + c)] = double(m(r, c));
    return pose;
}

/// A point from a 3-element single-channel CV_32F / CV_64F `cv::Mat` such as ORB-SLAM2's
/// `MapPoint::GetWorldPos()`; false for an empty Mat. Throws `std::invalid_argument` for any
/// other shape or type.
inline bool point_from_mat(const cv::Mat &mat, std::array<double, 3> &out)
{
    if (mat.empty())
        return false;
    if (mat.total() != 3 || (mat.type() != CV_32FC1 && mat.type() != CV_64FC1)) {
        throw std::invalid_argument("map point cv::Mat must hold 3 CV_32F/CV_64F values");
    }
    const cv::Mat m = mat.reshape(1, 3);
    for (int i = 0; i < 3; ++i)
        out[static_cast<std::size_t>(i)] =
            m.type() == CV_32FC1 ? double(m.at<float>(i, 0)) : m.at<double>(i, 0);
    return true;
}

/// A pose as ORB-SLAM2 keeps poses: a new 4x4 CV_32F `cv::Mat`.
[[nodiscard]] inline cv::Mat to_mat(const Pose &pose)
{
    cv::Mat mat(4, 4, CV_32F);
    for (int i = 0; i < 16; ++i)
        mat.at<float>(i / 4, i % 4) = float(pose[static_cast<std::size_t>(i)]);
    return mat;
}

/// The inverse of a rigid transform (`R^T`, `-R^T t`).
[[nodiscard]] inline Pose inverse_rigid(const Pose &T)
{
    Pose inv{0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    for (std::size_t r = 0; r < 3; ++r) {
        for (std::size_t c = 0; c < 3; ++c)
            inv[4 * r + c] = T[4 * c + r];
        inv[4 * r + 3] = -(T[r] * T[3] + T[4 + r] * T[7] + T[8 + r] * T[11]);
    }
    return inv;
}

/// `T * p` for a point `p`.
[[nodiscard]] inline std::array<double, 3> transform_point(const Pose &T,
                                                           const std::array<double, 3> &p)
{
    std::array<double, 3> out{};
    for (std::size_t r = 0; r < 3; ++r)
        out[r] = T[4 * r] * p[0] + T[4 * r + 1] * p[1] + T[4 * r + 2] * p[2] + T[4 * r + 3];
    return out;
}

// ---------------------------------------------------------------------------------------------
// Accessor
// ---------------------------------------------------------------------------------------------

/// The camera model of a keyframe's keypoints, as `Access::camera_model` tells it.
enum class CameraModel {
    /// `keypoints` are undistorted pinhole pixels of `intrinsics` (ORB-SLAM2, ORB-SLAM3's
    /// `Pinhole`).
    Pinhole,
    /// `keypoints` are raw fisheye pixels (ORB-SLAM3's `KannalaBrandt8`, whose `mvKeysUn` it
    /// does not undistort): the adapter turns each into its bearing (`Access::bearing`) and
    /// projects it through a pinhole of `intrinsics`; keypoints 87 degrees or more off the
    /// axis are left out.
    Fisheye,
    /// Anything else: the keyframe is refused with an error.
    Other,
};

/// How the database reads ORB-SLAM's objects. The defaults target ORB-SLAM2's shapes plus one
/// member the host adds (`cv::Mat mImGray` on `KeyFrame` and `Frame`, see README.md). For
/// ORB-SLAM3, derive from it and hide `camera_from_world`, `world_position` and `map_of`
/// (README.md has the lines). Every function is static, gets non-const references (ORB-SLAM's
/// getters lock and are not const), is called with the database's mutex held, and may throw:
/// the adapter turns an exception into an error of the call.
template <typename KeyFrame, typename Frame = KeyFrame> struct DefaultAccess {
    /// The keyframe id (`mnId`); must increase from one added keyframe to the next.
    static uint64_t id(KeyFrame &kf) { return static_cast<uint64_t>(kf.mnId); }
    /// Seconds (`mTimeStamp`); must not decrease.
    static double timestamp(KeyFrame &kf) { return kf.mTimeStamp; }
    /// The undistorted keypoints (`mvKeysUn`), in the pixels of `intrinsics`.
    static const std::vector<cv::KeyPoint> &keypoints(KeyFrame &kf) { return kf.mvKeysUn; }
    /// The pinhole intrinsics of `keypoints`: the keyframe's own `fx`, `fy`, `cx`, `cy`, which
    /// ORB-SLAM3 sets after it rectifies stereo or resizes images (its settings file's
    /// `Camera1.fx` ... are the raw camera's then).
    static Intrinsics intrinsics(KeyFrame &kf)
    {
        return {double(kf.fx), double(kf.fy), double(kf.cx), double(kf.cy)};
    }
    /// The camera model of `keypoints`: ORB-SLAM2 undistorts them to a pinhole.
    static CameraModel camera_model(KeyFrame &) { return CameraModel::Pinhole; }
    /// The bearing (a ray in the camera frame, any length, z forward) of a keypoint of a
    /// `CameraModel::Fisheye` keyframe; called for no other model.
    static std::array<double, 3> bearing(KeyFrame &, const cv::KeyPoint &k)
    {
        return {double(k.pt.x), double(k.pt.y), 1.0};
    }
    /// How many of the descriptors and map points belong to `keypoints` when the keyframe
    /// holds a second camera's after them (ORB-SLAM3's `NLeft` of a two-fisheye rig, whose
    /// `mvKeysUn` has `NLeft` rows and descriptors `NLeft + NRight`); -1 for one camera,
    /// whose rows are one per keypoint. ORB-SLAM2 has one camera.
    static int left_count(KeyFrame &) { return -1; }
    /// The keyframes ORB-SLAM connects to `kf` by covisibility (`GetConnectedKeyFrames()`):
    /// never loop candidates of `kf`, as in ORB-SLAM's own database.
    static auto connected(KeyFrame &kf) { return kf.GetConnectedKeyFrames(); }
    /// The ORB descriptors (`mDescriptors`): N x 32 CV_8U, row i = keypoint i.
    static const cv::Mat &descriptors(KeyFrame &kf) { return kf.mDescriptors; }
    /// The keyframe's 8-bit image (grey, BGR or BGRA): the member the host adds.
    static const cv::Mat &image(KeyFrame &kf) { return kf.mImGray; }
    /// The frame's 8-bit image, for relocalization: the member the host adds to `Frame`.
    static const cv::Mat &frame_image(Frame &f) { return f.mImGray; }
    /// `Tcw` (world to camera) or `std::nullopt` for none (every keyframe has one or none has).
    static std::optional<Pose> camera_from_world(KeyFrame &kf)
    {
        return pose_from_mat(kf.GetPose());
    }
    /// The map point of each keypoint (`GetMapPointMatches()`), null where none.
    static auto map_points(KeyFrame &kf) { return kf.GetMapPointMatches(); }
    /// The world position of one entry of `map_points` into `out`; false for none (null, bad).
    template <typename MapPoint>
    static bool world_position(MapPoint *mp, std::array<double, 3> &out)
    {
        return mp != nullptr && !mp->isBad() && point_from_mat(mp->GetWorldPos(), out);
    }
    /// True for a culled keyframe: skipped by `add`, never returned as a candidate.
    static bool is_bad(KeyFrame &kf) { return kf.isBad(); }
    /// Called once `kf` is in topoloc, which keeps what it needs, and for a keyframe culled
    /// before it was added: frees the image member the integration added (nothing else in
    /// ORB-SLAM reads it; a VGA image is 300 KB a keyframe). An exception it throws is ignored.
    static void added(KeyFrame &kf) { kf.mImGray.release(); }
    /// The map (session) the keyframe belongs to now: ORB-SLAM2 has one (null for all).
    static const void *map_of(KeyFrame &) { return nullptr; }
    /// Whether the keyframe's map was discarded (ORB-SLAM3's `GetMap()->IsBad()`): its
    /// keyframes are never candidates. ORB-SLAM2 has none.
    static bool map_is_bad(KeyFrame &) { return false; }
};

// ---------------------------------------------------------------------------------------------
// The database
// ---------------------------------------------------------------------------------------------

/// ORB-SLAM's `KeyFrameDatabase` over topoloc. It does not own the keyframes (ORB-SLAM does):
/// it keeps pointers to the ones added, until `erase`, `clearMap` or `clear`, which ORB-SLAM
/// calls before it deletes a keyframe. Not copyable or movable (it holds a mutex). See the top
/// of this header for errors and thread safety.
///
/// `DetectLoopCandidates` / `DetectNBestCandidates` add the keyframe to topoloc (ORB-SLAM
/// queries before it calls `add`) and keep its hint; the following `add` of the same keyframe is
/// then a no-op. `add` alone (ORB-SLAM's early-return paths) adds the keyframe too.
template <typename KeyFrame, typename Frame = KeyFrame,
          typename Access = DefaultAccess<KeyFrame, Frame>>
class KeyFrameDatabase {
public:
    using Match = LoopMatch<KeyFrame>; ///< A keyframe's hint with the keyframes resolved.

    /// A database for keyframes described with `map`'s describer (a map built from images, e.g.
    /// `topoloc::Map::build_from_images`; neither map nor options are kept). The intrinsics
    /// are read from the keyframes (`Access::intrinsics`): the first keyframe's replace
    /// `options.fx..cy`, so hints carry relative poses, and every later keyframe must have the
    /// same. Throws `topoloc::Error` (a map without describer, invalid options): the
    /// constructors are the only members that throw.
    explicit KeyFrameDatabase(const topoloc::Map &map,
                              const topoloc::LoopOptions &options = topoloc::default_loop_options(),
                              Settings settings = Settings())
        : kind_(map.descriptor_kind()), model_(map.descriptor_model()), dim_(map.dim()),
          options_(for_sensor(options, settings)), describer_(map),
          detector_(new_detector(nullptr, nullptr)), settings_(std::move(settings))
    {
        errors_.set_logger(std::move(settings_.logger));
    }

    /// As the other constructor, with the intrinsics known up front: a keyframe whose own
    /// (`Access::intrinsics`) differ is refused, e.g. a settings file's raw `Camera1.fx` when
    /// ORB-SLAM3 rectified or resized the images. Throws `topoloc::Error` (also for invalid
    /// intrinsics).
    KeyFrameDatabase(const topoloc::Map &map, const Intrinsics &intrinsics,
                     const topoloc::LoopOptions &options = topoloc::default_loop_options(),
                     Settings settings = Settings())
        : kind_(map.descriptor_kind()), model_(map.descriptor_model()), dim_(map.dim()),
          options_(for_sensor(options, settings)), describer_(map),
          detector_(new_detector(&intrinsics, nullptr)), settings_(std::move(settings)),
          intrinsics_(intrinsics)
    {
        errors_.set_logger(std::move(settings_.logger));
    }

    KeyFrameDatabase(const KeyFrameDatabase &) = delete;
    KeyFrameDatabase &operator=(const KeyFrameDatabase &) = delete;

    /// Adds `pKF` (ORB-SLAM's `add`): a no-op when it is already held (e.g. after a `Detect*`
    /// call for it) and for a culled (`isBad`) keyframe, which ORB-SLAM may still have queued for
    /// loop closing. Then calls `Access::added` (the default frees the keyframe's image).
    ///
    /// A keyframe of another map than the last added one (`Access::map_of`: ORB-SLAM3 started
    /// a new map after tracking was lost, or merged maps) begins a topoloc session
    /// (`topoloc::LoopDetector::begin_session`): the keyframes held, in another world frame,
    /// are then merge candidates at once, whatever the exclusion window, and the odometry gate
    /// does not compare poses across the two frames. Its timestamp may be earlier than the
    /// last one's (a new sequence); within a map time must not go back.
    ///
    /// Errors: null keyframe, id not above the last added one, duplicate id, earlier timestamp
    /// in the same map, a keyframe held before `clear()`, intrinsics other than the first
    /// keyframe's, unusable image, descriptors, keypoints, pose or map points, a topoloc
    /// error.
    void add(KeyFrame *pKF) noexcept
    {
        run("add", [&] { (void)ensure_added(pKF); });
    }

    /// Removes `pKF` (ORB-SLAM's `erase`, from `KeyFrame::SetBadFlag`). As in ORB-SLAM's own
    /// database, a keyframe never added is a no-op, apart from freeing its image
    /// (`Access::added`). Errors: null keyframe, a keyframe erased already, a keyframe held
    /// before `clear()` (its id and timestamp are read to tell).
    void erase(KeyFrame *pKF) noexcept
    {
        run("erase", [&] { erase_if_held(pKF); });
    }

    /// Forgets every keyframe and starts a fresh topoloc detector (ORB-SLAM's `clear`, on reset:
    /// keyframe ids may start again). Keyframes held before it are refused afterwards. Errors: a
    /// topoloc error creating the detector (the database is then unchanged).
    void clear() noexcept
    {
        run("clear", [&] { reset(); });
    }

    /// Removes every keyframe of map `pMap` (ORB-SLAM3's `clearMap`; compared with
    /// `Access::map_of`). ORB-SLAM3 calls it when it resets the active map, which it then
    /// reuses: when `pMap` is the last added keyframe's map, the next keyframe begins a new
    /// session, and its timestamp may be earlier (a new dataset). Errors: an accessor that
    /// throws (nothing is removed then).
    template <typename MapT> void clearMap(MapT *pMap) noexcept
    {
        run("clearMap", [&] {
            const void *map = static_cast<const void *>(pMap);
            for (uint64_t id : ids_in_map(map))
                erase_held(id);
            if (map == last_map_)
                map_reset_ = true;
        });
    }

    /// ORB-SLAM2's loop query: adds `pKF` if needed and returns the keyframe of its accepted hint
    /// (in the same map, not connected to `pKF` by covisibility), or nothing. `minScore` is
    /// ignored: topoloc's gates replace the DBoW2 score threshold. Errors: those of `add`.
    std::vector<KeyFrame *> DetectLoopCandidates(KeyFrame *pKF, float minScore) noexcept
    {
        static_cast<void>(minScore);
        std::vector<KeyFrame *> found;
        run("DetectLoopCandidates", [&] {
            KeyFrame *matched = candidate_of(pKF, ensure_added(pKF));
            if (matched != nullptr && Access::map_of(*matched) == Access::map_of(*pKF))
                found.push_back(matched);
        });
        return found;
    }

    /// ORB-SLAM3's loop and merge query: adds `pKF` if needed and appends the keyframe of its
    /// accepted hint to `vpLoopCand` (same map as `pKF`) or `vpMergeCand` (another map), at most
    /// `nNumCandidates` in each (topoloc gives at most one). As upstream, a keyframe connected
    /// to `pKF` by covisibility (`Access::connected`) or of a discarded map
    /// (`Access::map_is_bad`) is never a candidate. On error nothing is appended.
    void DetectNBestCandidates(KeyFrame *pKF, std::vector<KeyFrame *> &vpLoopCand,
                               std::vector<KeyFrame *> &vpMergeCand, int nNumCandidates) noexcept
    {
        KeyFrame *matched = nullptr;
        bool same_map = false;
        const bool ok = run("DetectNBestCandidates", [&] {
            matched = candidate_of(pKF, ensure_added(pKF));
            if (matched != nullptr)
                same_map = Access::map_of(*matched) == Access::map_of(*pKF);
        });
        if (!ok || matched == nullptr || nNumCandidates <= 0)
            return;
        append(same_map ? vpLoopCand : vpMergeCand, matched);
    }

    /// ORB-SLAM2's relocalization query: the held keyframes most similar to `F`'s image (global
    /// descriptors), most similar first, at most `Settings::relocalization_candidates`; erased
    /// and bad keyframes never. `F` is not added. Errors: null frame, no keyframe held yet,
    /// unusable image or one of another size than the keyframes', a topoloc error.
    std::vector<KeyFrame *> DetectRelocalizationCandidates(Frame *F) noexcept
    {
        return relocalize(F, nullptr, false);
    }

    /// ORB-SLAM3's relocalization query: as the other overload, keeping keyframes of `pMap`
    /// only (`Access::map_of`).
    template <typename MapT>
    std::vector<KeyFrame *> DetectRelocalizationCandidates(Frame *F, MapT *pMap) noexcept
    {
        return relocalize(F, static_cast<const void *>(pMap), true);
    }

    /// The hint topoloc gave `pKF` when it was added (accepted or not), or `std::nullopt` when it
    /// had no verified match. Errors: a keyframe not held.
    [[nodiscard]] std::optional<Match> GetHint(KeyFrame *pKF) noexcept
    {
        std::optional<Match> out;
        run("GetHint", [&] {
            const Entry &entry = by_id_.at(held_id(pKF));
            if (entry.hint.has_match)
                out = to_match(entry.hint, entry.kf);
        });
        return out;
    }

    /// The hints of earlier keyframes that topoloc accepted after the fact since the last call,
    /// oldest first: when a keyframe completes a consistency streak (`consistent_keyframes`),
    /// the streak's earlier keyframes, refused while it was short, are accepted too. ORB-SLAM had
    /// already processed those keyframes; a host can add them as extra loop constraints. Hints
    /// whose keyframes were erased since are dropped.
    [[nodiscard]] std::vector<Match> TakeConfirmed() noexcept
    {
        std::vector<Match> out;
        run("TakeConfirmed", [&] {
            out = std::move(confirmed_);
            confirmed_.clear();
        });
        return out;
    }

    /// Saves topoloc's keyframes (global descriptors, keypoints, scene points, poses, place
    /// graph) as a topoloc map file, atomically, beside ORB-SLAM3's saved atlas (call it from
    /// `System::SaveAtlas`); `Load` opens it in a later run. Returns whether it succeeded.
    /// Errors: an empty database, an I/O error.
    bool Save(const std::string &path) noexcept
    {
        return run("Save", [&] { detector_.save(path); });
    }

    /// Opens a database saved with `Save`, before any keyframe is added (call it from
    /// `System::LoadAtlas`, before `Map::PostLoad` adds the loaded keyframes). The loaded
    /// keyframes, which ORB-SLAM3 restores without images, are then matched by id as
    /// `add` meets them, and are candidates again; new keyframes need larger ids (ORB-SLAM3
    /// restores its id counter) and begin a new session. Returns whether it succeeded.
    /// Errors: a database that holds keyframes, a file that is not a topoloc map, a map of
    /// another describer or not saved by `Save` (views without keyframe ids), a topoloc error.
    /// On error the database is unchanged.
    bool Load(const std::string &path) noexcept
    {
        return run("Load", [&] { load(path); });
    }

    /// Frees topoloc's detector and describer (and their ONNX Runtime sessions) while the
    /// host's libraries are still alive: call it from `System::Shutdown` once the loop closing
    /// thread has finished. Every later call fails with "the database was shut down".
    void Shutdown() noexcept
    {
        std::lock_guard<std::mutex> lock(mutex_);
        shut_down_ = true;
        detector_ = topoloc::LoopDetector();
        describer_ = topoloc::Describer();
        saved_.reset();
    }

    /// Number of keyframes held.
    [[nodiscard]] std::size_t size() const noexcept
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return by_id_.size();
    }

    /// Whether `pKF` is held (added and not erased or cleared).
    [[nodiscard]] bool contains(KeyFrame *pKF) const noexcept
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return by_ptr_.count(pKF) != 0;
    }

    /// The error of the calling thread's last call ("" when it succeeded): "<call>: <reason>".
    [[nodiscard]] std::string last_error() const
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return errors_.last_error();
    }

    /// How many calls failed since construction (all threads).
    [[nodiscard]] std::size_t error_count() const noexcept
    {
        std::lock_guard<std::mutex> lock(mutex_);
        return errors_.error_count();
    }

    /// Replaces the logger of `Settings::logger` (empty = none).
    void SetLogger(topoloc_adapter::Logger logger) noexcept
    {
        std::lock_guard<std::mutex> lock(mutex_);
        errors_.set_logger(std::move(logger));
    }

private:
    /// One held keyframe and the hint topoloc gave it.
    struct Entry {
        KeyFrame *kf = nullptr;
        double timestamp = 0.0; // as added: `clear()` reads nothing from the keyframes
        topoloc::LoopHint hint;
    };

    /// What identifies a keyframe held before `clear()`: its address, id and timestamp (an
    /// address alone may be reused by a new keyframe).
    using Identity = std::tuple<const KeyFrame *, uint64_t, double>;

    /// The options for the sensor: a monocular map has no metric odometry to gate with.
    static topoloc::LoopOptions for_sensor(topoloc::LoopOptions options, const Settings &settings)
    {
        if (settings.max_keypoints < 1 || settings.max_keypoints > kMaxKeypoints)
            throw topoloc::Error(TOPOLOC_ERR_INVALID_ARGUMENT,
                                 "Settings::max_keypoints is " +
                                     std::to_string(settings.max_keypoints) +
                                     ", must lie in 1..=" + std::to_string(kMaxKeypoints));
        if (settings.monocular)
            options.odometry_gate = false;
        return options;
    }

    /// A detector with `intrinsics` (null: without, until the first keyframe gives them),
    /// whose first session is the saved one `Load` opened, if any.
    topoloc::LoopDetector new_detector(const Intrinsics *intrinsics) const
    {
        return new_detector(intrinsics, saved_ ? &*saved_ : nullptr);
    }

    topoloc::LoopDetector new_detector(const Intrinsics *intrinsics,
                                       const topoloc::Map *saved) const
    {
        topoloc::LoopOptions options = options_;
        if (intrinsics != nullptr) {
            options.fx = intrinsics->fx;
            options.fy = intrinsics->fy;
            options.cx = intrinsics->cx;
            options.cy = intrinsics->cy;
        }
        return saved != nullptr ? topoloc::LoopDetector::from_map(*saved, options)
                                : topoloc::LoopDetector::create(kind_, model_, dim_, options);
    }

    /// Makes `first` (from `check_intrinsics`, once the keyframe is in it) the detector, with
    /// `kf`'s intrinsics as the run's; nothing for none.
    void adopt(std::optional<topoloc::LoopDetector> &first, KeyFrame &kf)
    {
        if (!first)
            return;
        detector_ = std::move(*first);
        intrinsics_ = Access::intrinsics(kf);
    }

    /// Refuses a keyframe whose intrinsics differ from the run's; before the first keyframe of
    /// a run without intrinsics, returns the detector that takes the keyframe's.
    std::optional<topoloc::LoopDetector> check_intrinsics(KeyFrame &kf, uint64_t id) const
    {
        const Intrinsics k = Access::intrinsics(kf);
        if (!intrinsics_)
            return new_detector(&k); // throws for unusable intrinsics
        const auto differs = [](double a, double b) {
            return !(std::abs(a - b) <= 1e-6 * std::max(1.0, std::abs(b)));
        };
        const Intrinsics &run = *intrinsics_;
        if (differs(k.fx, run.fx) || differs(k.fy, run.fy) || differs(k.cx, run.cx) ||
            differs(k.cy, run.cy)) {
            fail("keyframe " + std::to_string(id) + " has intrinsics fx " + std::to_string(k.fx) +
                 " fy " + std::to_string(k.fy) + " cx " + std::to_string(k.cx) + " cy " +
                 std::to_string(k.cy) + ", not the run's " + std::to_string(run.fx) + " " +
                 std::to_string(run.fy) + " " + std::to_string(run.cx) + " " +
                 std::to_string(run.cy) + " (pass the keyframes' fx..cy, not the settings file's)");
        }
        return std::nullopt;
    }

    static void fail(const std::string &message) { throw std::runtime_error(message); }

    /// Runs `body` under the mutex, records its outcome for the calling thread, and logs a
    /// failure after unlocking. Returns whether it succeeded.
    template <typename Body> bool run(const char *call, Body &&body) noexcept
    {
        std::string error;
        topoloc_adapter::Logger logger;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            error = shut_down_ ? describe_failure(call, "the database was shut down (Shutdown)")
                               : attempt(call, body);
            logger = errors_.record(error);
        }
        topoloc_adapter::log(logger, error);
        return error.empty();
    }

    /// `body()`, its failure turned into "<call>: <reason>" ("" on success).
    template <typename Body> static std::string attempt(const char *call, Body &body) noexcept
    {
        try {
            body();
            return std::string();
        } catch (const std::exception &e) {
            return describe_failure(call, e.what());
        } catch (...) {
            return describe_failure(call, "unknown exception");
        }
    }

    static std::string describe_failure(const char *call, const char *reason) noexcept
    {
        try {
            return std::string(call) + ": " + reason;
        } catch (...) {
            return std::string(); // out of memory: nothing better to report
        }
    }

    // --- keyframes in ---------------------------------------------------------------------------

    /// The entry of `kf`, adding it first when it is not held; null for a culled keyframe
    /// (skipped). Throws on any refusal, before anything changed.
    const Entry *ensure_added(KeyFrame *kf)
    {
        if (kf == nullptr)
            fail("null keyframe");
        const auto held = by_ptr_.find(kf);
        if (held != by_ptr_.end())
            return &by_id_.at(held->second);
        const uint64_t id = Access::id(*kf);
        const double timestamp = Access::timestamp(*kf);
        if (retired_.count(Identity(kf, id, timestamp)) != 0)
            fail(retired_message(id));
        if (Access::is_bad(*kf)) {
            release_image(*kf);
            return nullptr;
        }
        if (saved_ids_.count(id) != 0)
            return &bind_saved(kf, id, timestamp);
        const void *map = Access::map_of(*kf);
        const bool new_session = last_id_.has_value() && (map != last_map_ || map_reset_);
        check_order(id, timestamp, new_session);
        std::optional<topoloc::LoopDetector> first = check_intrinsics(*kf, id);
        topoloc::LoopKeyframe keyframe = assemble(*kf, id, timestamp);
        const cv::Size size = Access::image(*kf).size();
        topoloc::LoopDetector &detector = first ? *first : detector_;
        if (new_session)
            detector.begin_session();
        const topoloc::LoopHint hint = detector.add(keyframe);
        adopt(first, *kf);
        const Entry &entry = commit(kf, id, timestamp, size, hint);
        last_map_ = map;
        map_reset_ = false;
        release_image(*kf);
        return &entry;
    }

    /// Takes `kf` as the saved keyframe `id` that `Load` brought back (ORB-SLAM3's
    /// `Map::PostLoad` adds its loaded keyframes, which have no image): topoloc holds it
    /// already, with its features. Throws, before anything changed, for intrinsics other than
    /// the run's.
    const Entry &bind_saved(KeyFrame *kf, uint64_t id, double timestamp)
    {
        std::optional<topoloc::LoopDetector> first = check_intrinsics(*kf, id);
        topoloc::LoopHint none;
        none.query_id = id;
        Entry &entry = by_id_[id];
        entry.kf = kf;
        entry.timestamp = timestamp;
        entry.hint = none;
        try {
            by_ptr_[kf] = id;
            saved_ids_.erase(id);
        } catch (...) {
            by_id_.erase(id);
            throw;
        }
        adopt(first, *kf);
        last_map_ = Access::map_of(*kf);
        release_image(*kf);
        return entry;
    }

    /// `Access::added`, whose exceptions are ignored (as documented there).
    static void release_image(KeyFrame &kf) noexcept
    {
        try {
            Access::added(kf);
        } catch (...) {
        }
    }

    static std::string retired_message(uint64_t id)
    {
        return "keyframe " + std::to_string(id) +
               " was added before clear(): the database was reset since";
    }

    /// Refuses a keyframe out of order: a held id, an id not above the last, an earlier time
    /// (unless it starts a new session).
    void check_order(uint64_t id, double timestamp, bool new_session) const
    {
        const std::string name = "keyframe " + std::to_string(id);
        if (by_id_.count(id) != 0)
            fail(name + ": another keyframe with this id is held");
        if (last_id_ && id <= *last_id_)
            fail(name + " after keyframe " + std::to_string(*last_id_) + ": ids must increase");
        if (!std::isfinite(timestamp))
            fail(name + ": timestamp is not finite");
        if (last_id_ && !new_session && timestamp < last_timestamp_)
            fail(name + ": timestamp " + std::to_string(timestamp) +
                 " is earlier than the last one");
    }

    /// The topoloc keyframe of `kf`: keypoints, ORB descriptors, image descriptor, pose and
    /// scene points. Throws on unusable data.
    topoloc::LoopKeyframe assemble(KeyFrame &kf, uint64_t id, double timestamp)
    {
        topoloc::LoopKeyframe out;
        out.id = id;
        out.timestamp = timestamp;
        const std::vector<cv::KeyPoint> &keys = Access::keypoints(kf);
        const Rows rows = rows_of(kf, keys.size());
        const MapPoints points = map_points_of(kf, rows);
        const std::vector<std::size_t> kept =
            pinhole_keypoints(kf, keys, points, settings_.max_keypoints, out.keypoints);
        out.keypoint_descriptors = descriptor_bytes(Access::descriptors(kf), rows, kept);
        out.descriptor = describe(Access::image(kf), "keyframe image");
        const std::optional<Pose> Tcw = Access::camera_from_world(kf);
        if (Tcw) {
            check_pose(*Tcw);
            out.world_T_body = inverse_rigid(*Tcw); // Twc; the body is the camera
            out.camera_points = camera_points(*Tcw, rows, points, kept);
        }
        return out;
    }

    /// How many descriptor and map point rows a keyframe must have: exactly one per keypoint
    /// (one camera), or at least one per keypoint (a second camera's rows follow).
    struct Rows {
        std::size_t count = 0;
        bool more_allowed = false;
        [[nodiscard]] bool fits(std::size_t rows) const
        {
            return more_allowed ? rows >= count : rows == count;
        }
        [[nodiscard]] std::string text() const
        {
            return (more_allowed ? "at least " : "") + std::to_string(count);
        }
    };

    /// The world positions of a keyframe's map point matches, read once per keyframe.
    struct MapPoints {
        std::size_t matches = 0; ///< How many matches the keyframe has (rows of all cameras).
        /// Per keypoint, its usable map point's position; empty when `matches` does not fit
        /// the keypoints (`camera_points` reports that).
        std::vector<std::optional<std::array<double, 3>>> world;
        [[nodiscard]] bool has(std::size_t keypoint) const
        {
            return keypoint < world.size() && world[keypoint].has_value();
        }
    };

    static MapPoints map_points_of(KeyFrame &kf, const Rows &rows)
    {
        const auto matches = Access::map_points(kf);
        MapPoints out;
        out.matches = static_cast<std::size_t>(matches.size());
        if (!rows.fits(out.matches))
            return out;
        out.world.resize(rows.count);
        for (std::size_t i = 0; i < rows.count; ++i) {
            std::array<double, 3> Xw{};
            if (Access::world_position(matches[i], Xw))
                out.world[i] = Xw;
        }
        return out;
    }

    static Rows rows_of(KeyFrame &kf, std::size_t keypoints)
    {
        const int left = Access::left_count(kf);
        if (left < 0)
            return {keypoints, false};
        if (static_cast<std::size_t>(left) != keypoints)
            fail("left_count (NLeft) is " + std::to_string(left) + " for " +
                 std::to_string(keypoints) + " keypoints");
        return {keypoints, true};
    }

    /// Writes the pinhole pixel positions of the usable keypoints into `xy` and returns their
    /// indices: all of a pinhole keyframe's, a fisheye keyframe's bearings projected through
    /// the keyframe's intrinsics; `limit` of them when there are more (`keep_strongest`).
    /// Throws for another camera model.
    static std::vector<std::size_t> pinhole_keypoints(KeyFrame &kf,
                                                      const std::vector<cv::KeyPoint> &keys,
                                                      const MapPoints &points, std::size_t limit,
                                                      std::vector<float> &xy)
    {
        const CameraModel model = Access::camera_model(kf);
        if (model == CameraModel::Other)
            fail("the keyframe's camera model is neither pinhole nor Kannala-Brandt fisheye");
        const Intrinsics k = model == CameraModel::Fisheye ? Access::intrinsics(kf) : Intrinsics{};
        std::vector<std::size_t> kept;
        std::vector<cv::Point2f> pixels;
        kept.reserve(keys.size());
        pixels.reserve(keys.size());
        for (std::size_t i = 0; i < keys.size(); ++i) {
            cv::Point2f px = keys[i].pt;
            if (model == CameraModel::Fisheye) {
                const std::array<double, 3> ray = Access::bearing(kf, keys[i]);
                const double norm = std::sqrt(ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2]);
                if (!(ray[2] > kMinBearingZ * norm)) // also NaN
                    continue;
                px = cv::Point2f(float(k.fx * ray[0] / ray[2] + k.cx),
                                 float(k.fy * ray[1] / ray[2] + k.cy));
            }
            kept.push_back(i);
            pixels.push_back(px);
        }
        if (kept.size() > limit)
            keep_strongest(keys, points, limit, kept, pixels);
        xy.reserve(2 * pixels.size());
        for (const cv::Point2f &px : pixels) {
            xy.push_back(px.x);
            xy.push_back(px.y);
        }
        return kept;
    }

    /// Keeps `limit` of `kept` (indices into `keys`, with their `pixels`): those with a map
    /// point first, then the highest responses; in their original order.
    static void keep_strongest(const std::vector<cv::KeyPoint> &keys, const MapPoints &points,
                               std::size_t limit, std::vector<std::size_t> &kept,
                               std::vector<cv::Point2f> &pixels)
    {
        std::vector<std::size_t> order(kept.size());
        for (std::size_t j = 0; j < order.size(); ++j)
            order[j] = j;
        std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
            const bool pa = points.has(kept[a]), pb = points.has(kept[b]);
            if (pa != pb)
                return pa;
            return keys[kept[a]].response > keys[kept[b]].response;
        });
        order.resize(limit);
        std::sort(order.begin(), order.end());
        std::vector<std::size_t> strongest;
        std::vector<cv::Point2f> strongest_pixels;
        strongest.reserve(order.size());
        strongest_pixels.reserve(order.size());
        for (std::size_t j : order) {
            strongest.push_back(kept[j]);
            strongest_pixels.push_back(pixels[j]);
        }
        kept = std::move(strongest);
        pixels = std::move(strongest_pixels);
    }

    /// The rows `kept` of an N x 32 CV_8U descriptor matrix, whose row count must fit `rows`.
    static std::vector<uint8_t> descriptor_bytes(const cv::Mat &d, const Rows &rows,
                                                 const std::vector<std::size_t> &kept)
    {
        if (rows.count == 0 && d.empty())
            return {};
        if (d.dims != 2 || d.type() != CV_8UC1 || d.cols != 32 ||
            !rows.fits(static_cast<std::size_t>(d.rows))) {
            fail("descriptors must be " + rows.text() + " x 32 CV_8U (one row per keypoint), " +
                 "got " + std::to_string(d.rows) + " x " + std::to_string(d.cols) + " of type " +
                 std::to_string(d.type()));
        }
        std::vector<uint8_t> bytes(32 * kept.size());
        for (std::size_t j = 0; j < kept.size(); ++j) {
            const uint8_t *row = d.ptr<uint8_t>(int(kept[j]));
            std::copy(row, row + 32, bytes.begin() + std::ptrdiff_t(32 * j));
        }
        return bytes;
    }

    static void check_pose(const Pose &T)
    {
        for (double v : T)
            if (!std::isfinite(v))
                fail("pose Tcw has a NaN or infinite value");
        if (T[12] != 0.0 || T[13] != 0.0 || T[14] != 0.0 || T[15] != 1.0)
            fail("pose Tcw's last row is not 0 0 0 1");
    }

    /// The map point of each kept keypoint in the camera frame (`Tcw * Xw`), NaN x3 where
    /// none; the map point rows must fit `rows`.
    static std::vector<float> camera_points(const Pose &Tcw, const Rows &rows,
                                            const MapPoints &points,
                                            const std::vector<std::size_t> &kept)
    {
        if (!rows.fits(points.matches))
            fail(std::to_string(points.matches) + " map point matches for " + rows.text() +
                 " keypoints");
        const float nan = std::numeric_limits<float>::quiet_NaN();
        std::vector<float> xyz(3 * kept.size(), nan);
        for (std::size_t j = 0; j < kept.size(); ++j)
            if (points.has(kept[j]))
                write_point(transform_point(Tcw, *points.world[kept[j]]), &xyz[3 * j]);
        return xyz;
    }

    /// Writes a finite point (a non-finite one stays NaN: unknown).
    static void write_point(const std::array<double, 3> &p, float *out)
    {
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            return;
        for (std::size_t k = 0; k < 3; ++k)
            out[k] = float(p[k]);
    }

    /// The global descriptor of an image, which must have the first keyframe's size.
    std::vector<float> describe(const cv::Mat &image, const char *what)
    {
        if (image.empty())
            fail(std::string(what) + " is empty (is the image member set?)");
        const std::string size = image_size_.mismatch(image.size(), what);
        if (!size.empty())
            fail(size);
        return describer_.describe(topoloc::image_view(image));
    }

    /// Records an added keyframe (topoloc has it), and the hints it confirmed.
    const Entry &commit(KeyFrame *kf, uint64_t id, double timestamp, cv::Size size,
                        const topoloc::LoopHint &hint)
    {
        try {
            Entry &entry = by_id_[id];
            entry.kf = kf;
            entry.timestamp = timestamp;
            entry.hint = hint;
            by_ptr_[kf] = id;
            take_confirmed_hints();
        } catch (...) { // out of memory: undo, so that topoloc and the index agree
            forget(id, kf);
            throw;
        }
        last_id_ = id;
        last_timestamp_ = timestamp;
        image_size_.remember(size);
        return by_id_.at(id);
    }

    /// Moves the detector's confirmed hints into the entries and the `TakeConfirmed` queue.
    void take_confirmed_hints()
    {
        for (const topoloc::LoopHint &hint : detector_.confirmed()) {
            const auto it = by_id_.find(hint.query_id);
            if (it == by_id_.end())
                continue;
            it->second.hint = hint;
            confirmed_.push_back(to_match(hint, it->second.kf));
        }
    }

    void forget(uint64_t id, KeyFrame *kf) noexcept
    {
        try {
            detector_.erase(id);
        } catch (...) {
        }
        by_id_.erase(id);
        by_ptr_.erase(kf);
    }

    // --- keyframes out --------------------------------------------------------------------------

    void erase_if_held(KeyFrame *kf)
    {
        if (kf == nullptr)
            fail("null keyframe");
        const auto it = by_ptr_.find(kf);
        if (it != by_ptr_.end())
            return erase_held(it->second);
        const auto retired =
            retired_.lower_bound(Identity(kf, 0, -std::numeric_limits<double>::infinity()));
        if (retired == retired_.end() || std::get<0>(*retired) != kf) {
            const uint64_t id = Access::id(*kf);
            if (erased_.count(Identity(kf, id, Access::timestamp(*kf))) != 0)
                fail("keyframe " + std::to_string(id) + " was erased already");
            release_image(*kf); // never added: culled before the loop closing thread took it
            return;
        }
        const uint64_t id = Access::id(*kf);
        if (retired_.count(Identity(kf, id, Access::timestamp(*kf))) != 0)
            fail(retired_message(id));
    }

    uint64_t held_id(KeyFrame *kf) const
    {
        const auto it = by_ptr_.find(kf);
        if (it == by_ptr_.end())
            fail(kf == nullptr ? std::string("null keyframe")
                               : "keyframe is not in the database (never added, erased, or added "
                                 "before clear())");
        return it->second;
    }

    /// `Load`'s body: the checks first, then everything is swapped in.
    void load(const std::string &path)
    {
        if (!by_id_.empty() || last_id_)
            fail("Load needs an empty database: call it before any keyframe is added");
        topoloc::Map map = topoloc::Map::load(path);
        if (map.descriptor_kind() != kind_ || map.descriptor_model() != model_ ||
            map.dim() != dim_) {
            fail(path + " holds " + map.descriptor_kind() + "/" + map.descriptor_model() + " " +
                 std::to_string(map.dim()) + "-d descriptors, this database describes with " +
                 kind_ + "/" + model_ + " " + std::to_string(dim_));
        }
        std::set<uint64_t> ids;
        for (uint32_t v = 0; v < map.view_count(); ++v) {
            const std::optional<uint64_t> id = map.view_info(v).keyframe_id;
            if (!id)
                fail(path + ": view " + std::to_string(v) +
                     " has no keyframe id (not a database saved by Save)");
            ids.insert(*id);
        }
        topoloc::LoopDetector fresh = new_detector(intrinsics_ ? &*intrinsics_ : nullptr, &map);
        detector_ = std::move(fresh);
        last_id_ = ids.empty() ? std::nullopt : std::optional<uint64_t>(*ids.rbegin());
        saved_ids_.swap(ids);
        saved_ = std::move(map);
    }

    /// Erases held keyframe `id` from topoloc and the index, and drops hints naming it.
    void erase_held(uint64_t id)
    {
        const Entry &held = by_id_.at(id);
        erased_.insert(Identity(held.kf, id, held.timestamp)); // first: may throw, nothing done
        try {
            detector_.erase(id);
        } catch (...) { // topoloc does not hold it: nothing changed
            erased_.erase(Identity(held.kf, id, held.timestamp));
            throw;
        }
        KeyFrame *kf = by_id_.at(id).kf;
        by_id_.erase(id);
        by_ptr_.erase(kf);
        std::vector<Match> kept;
        for (Match &m : confirmed_)
            if (m.query != kf && m.matched != kf)
                kept.push_back(m);
        confirmed_.swap(kept);
    }

    std::vector<uint64_t> ids_in_map(const void *map) const
    {
        std::vector<uint64_t> ids;
        for (const auto &[id, entry] : by_id_)
            if (Access::map_of(*entry.kf) == map)
                ids.push_back(id);
        return ids;
    }

    void reset()
    {
        // May throw: nothing changed yet.
        topoloc::LoopDetector fresh = new_detector(intrinsics_ ? &*intrinsics_ : nullptr);
        std::set<Identity> retired;
        for (const auto &[id, entry] : by_id_)
            retired.insert(Identity(entry.kf, id, entry.timestamp));
        detector_ = std::move(fresh);
        retired_.swap(retired);
        erased_.clear();
        saved_.reset();
        saved_ids_.clear();
        by_id_.clear();
        by_ptr_.clear();
        confirmed_.clear();
        last_id_.reset();
        last_map_ = nullptr;
        map_reset_ = false;
        last_timestamp_ = 0.0;
        image_size_.reset();
    }

    /// The held, good keyframe with id `id`, or null.
    KeyFrame *usable(uint64_t id) const
    {
        const auto it = by_id_.find(id);
        if (it == by_id_.end() || Access::is_bad(*it->second.kf))
            return nullptr;
        return it->second.kf;
    }

    /// The matched keyframe of an accepted hint of `query`, if still usable, of a map not
    /// discarded and not connected to `query` by covisibility (null for no entry).
    KeyFrame *candidate_of(KeyFrame *query, const Entry *entry) const
    {
        KeyFrame *matched =
            entry != nullptr && entry->hint.accepted ? usable(entry->hint.matched_id) : nullptr;
        if (matched == nullptr || Access::map_is_bad(*matched))
            return nullptr;
        for (KeyFrame *connected : Access::connected(*query))
            if (connected == matched)
                return nullptr;
        return matched;
    }

    static void append(std::vector<KeyFrame *> &to, KeyFrame *kf) noexcept
    {
        try {
            to.push_back(kf);
        } catch (...) {
        }
    }

    std::vector<KeyFrame *> relocalize(Frame *F, const void *map, bool by_map) noexcept
    {
        std::vector<KeyFrame *> found;
        const bool ok = run("DetectRelocalizationCandidates", [&] {
            if (F == nullptr)
                fail("null frame");
            if (by_id_.empty())
                fail("no keyframe is held yet: nothing to relocalize against");
            const std::vector<float> d = describe(Access::frame_image(*F), "frame image");
            for (const topoloc::LoopCandidate &c : detector_.query(d, by_id_.size())) {
                if (found.size() >= settings_.relocalization_candidates)
                    break;
                KeyFrame *kf = usable(c.keyframe_id);
                if (kf != nullptr && (!by_map || Access::map_of(*kf) == map))
                    found.push_back(kf);
            }
        });
        if (!ok)
            found.clear();
        return found;
    }

    Match to_match(const topoloc::LoopHint &hint, KeyFrame *query) const
    {
        Match m;
        static_cast<topoloc::LoopHint &>(m) = hint;
        m.query = query;
        m.matched = hint.has_match ? usable(hint.matched_id) : nullptr;
        m.query_T_matched = inverse_rigid(hint.matched_T_query);
        return m;
    }

    const std::string kind_;
    const std::string model_;
    const uint32_t dim_;
    const topoloc::LoopOptions options_;

    mutable std::mutex mutex_; // guards everything below
    topoloc::Describer describer_;
    topoloc::LoopDetector detector_;
    Settings settings_;
    std::map<uint64_t, Entry> by_id_;
    std::unordered_map<const KeyFrame *, uint64_t> by_ptr_;
    std::set<Identity> retired_; // held at the last clear()
    std::set<Identity> erased_;  // erased since the last clear()
    std::vector<Match> confirmed_;
    std::optional<Intrinsics> intrinsics_; // the run's: given, or the first keyframe's
    std::optional<topoloc::Map> saved_;    // opened by Load: the detector's first session
    std::set<uint64_t> saved_ids_;         // its keyframes not bound to ORB-SLAM's yet
    bool shut_down_ = false;
    std::optional<uint64_t> last_id_;
    double last_timestamp_ = 0.0;
    const void *last_map_ = nullptr; // the last added keyframe's (Access::map_of)
    bool map_reset_ = false;         // clearMap emptied last_map_: the next keyframe starts anew
    topoloc_adapter::ImageSize image_size_;
    topoloc_adapter::ErrorReport errors_;
};

} // namespace topoloc_orbslam

#endif // TOPOLOC_ORBSLAM_HPP
