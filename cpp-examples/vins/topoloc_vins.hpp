// topoloc as the loop detector of VINS-Fusion's loop_fusion (VINS-Mono alike): the contract of
// its `PoseGraph::detectLoop` and `KeyFrame::findConnection`, over include/topoloc.hpp.
//
// `detectLoop(keyframe, index)` gives the index of the old keyframe the new one closes a loop
// with, or -1; `findConnection(index, old_index, info)` gives what VINS's own findConnection
// computes for the 4-DoF pose graph: the relative translation and rotation of the new body (IMU)
// frame in the old one's, and the relative yaw, packed as VINS's `loop_info`
// [tx ty tz qw qx qy qz yaw_deg]. Candidates are verified by topoloc (fundamental matrix, PnP
// against the old keyframe's 3D points, the odometry gate) instead of DBoW2 + BRIEF + PnP.
//
// No ROS, no VINS code: this file copies nothing from VINS-Fusion (GPL-3); it reproduces the
// contract a pose graph sees. Header-only, C++17, needs Eigen and OpenCV (as VINS does).
#ifndef TOPOLOC_VINS_HPP
#define TOPOLOC_VINS_HPP

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "topoloc.hpp"

#include "../common/adapter_support.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace topoloc_vins {

/// A 256-bit binary descriptor (VINS's BRIEF, ORB) as 32 bytes. From VINS's
/// `boost::dynamic_bitset<>`: copy its blocks with `boost::to_block_range` (README).
using Descriptor = std::array<uint8_t, 32>;

/// One keyframe as loop_fusion has it. Borrowed by `LoopDetector::detectLoop` for the call.
///
/// Points: VINS's images are raw (distorted, or fisheye), and so are its pixel coordinates
/// (`point_2d_uv`, `keypoints`). Give the normalized undistorted coordinates VINS computes
/// with its camera model (`point_2d_norm`, `keypoints_norm`): the adapter projects them
/// through the pinhole `Config::fx..cy`. Pixel arrays are used only where no normalized ones
/// are given, and must then be undistorted pinhole pixels of `Config::fx..cy`.
struct KeyFrame {
    /// VINS's keyframe index; must increase from one keyframe to the next.
    int index = -1;
    /// Seconds; must not decrease within a sequence.
    double time_stamp = 0.0;
    /// VINS's `sequence`: a keyframe of another sequence than the last one begins a topoloc
    /// session (`topoloc::LoopDetector::begin_session`), whose clock may restart and whose VIO
    /// frame is not compared with the earlier sequences' by the odometry gate.
    int sequence = 0;
    /// The keyframe image (CV_8UC1 grey or CV_8UC3 BGR), raw as VINS has it; every keyframe
    /// the size of the first. Only its global descriptor is computed from it, unless the
    /// keyframe brings no points (ORB corners are then extracted: the image must then be
    /// undistorted to the pinhole `Config::fx..cy`).
    cv::Mat image;
    /// VIO pose of the body (IMU) in the VIO world: `vio_T_w_i`, `vio_R_w_i` (after VINS's
    /// shift of a merged sequence): the odometry topoloc's gate compares.
    Eigen::Vector3d vio_T_w_i = Eigen::Vector3d::Zero();
    Eigen::Matrix3d vio_R_w_i = Eigen::Matrix3d::Identity();
    /// The pose `point_3d` was triangulated in (VINS `origin_vio_T`, `origin_vio_R`, which
    /// its own PnP uses); none = the VIO pose. Both or neither.
    std::optional<Eigen::Vector3d> origin_vio_T;
    std::optional<Eigen::Matrix3d> origin_vio_R;
    /// Optional: the tracked points of the sliding window, with their VIO world positions
    /// (`point_3d`), normalized coordinates (`point_2d_norm`) or undistorted pixels
    /// (`point_2d_uv`), and descriptors (VINS: `window_brief_descriptors`); all the same
    /// length (each coordinate array may be empty).
    std::vector<cv::Point3f> point_3d;
    std::vector<cv::Point2f> point_2d_norm;
    std::vector<cv::Point2f> point_2d_uv;
    std::vector<Descriptor> window_descriptors;
    /// Optional: further keypoints without 3D (VINS: `keypoints_norm` / `keypoints` and
    /// `brief_descriptors`, its extra FAST corners); the same length.
    std::vector<cv::Point2f> keypoints_norm;
    std::vector<cv::Point2f> keypoints;
    std::vector<Descriptor> descriptors;
};

/// What VINS's findConnection computes for a loop: the new keyframe `cur_index`'s body in the
/// old keyframe `old_index`'s body frame, and the yaw between them.
struct LoopInfo {
    int cur_index = -1;
    int old_index = -1;
    /// `R_old^T (t_cur - t_old)`, metres (VINS `relative_t`).
    Eigen::Vector3d relative_t = Eigen::Vector3d::Zero();
    /// `R_old^T R_cur` (VINS `relative_q`).
    Eigen::Quaterniond relative_q = Eigen::Quaterniond::Identity();
    /// yaw(R_cur) - yaw(R_old) in degrees, (-180, 180], as VINS computes it from the VIO
    /// rotation of the new keyframe and the loop's rotation of the old one.
    double relative_yaw = 0.0;
    /// Covariance of the relative pose (body frames, right perturbation), GTSAM Pose3 order:
    /// rotation (rad) x y z, then translation (m) x y z.
    Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
    /// Fundamental-matrix inliers of the pair.
    uint32_t inliers = 0;

    /// VINS's `loop_info`: [tx ty tz qw qx qy qz yaw_deg].
    Eigen::Matrix<double, 8, 1> loop_info() const
    {
        Eigen::Matrix<double, 8, 1> v;
        v << relative_t, relative_q.w(), relative_q.x(), relative_q.y(), relative_q.z(),
            relative_yaw;
        return v;
    }
};

/// What `PoseGraph::addKeyFrame` writes after `detectLoop`, in VINS's terms
/// (`LoopDetector::pose_graph_update`).
struct PoseGraphUpdate {
    /// The loops to record: the current keyframe's (if any), then those `confirmed()` gave.
    /// For each, set `has_loop`, `loop_index` (= `old_index`) and `loop_info` on keyframe
    /// `cur_index`, holding `m_keyframelist`: the optimisation thread reads them.
    std::vector<LoopInfo> loops;
    /// VINS's `earliest_loop_index` after these loops: the smallest old index of every loop so
    /// far, -1 for none. `optimize4DoF` starts there and asserts that each loop's old index is
    /// at or after it, so a confirmed loop that reaches further back must lower it.
    int earliest_loop_index = -1;
    /// The one index to push to `optimize_buf` (-1: none): the current keyframe's whenever a
    /// loop was recorded. `optimize4DoF` optimizes up to the last index pushed, so pushing a
    /// confirmed loop's earlier index after it would leave the current loop out.
    int optimize_index = -1;
};

/// Configuration: the camera and its extrinsics, the exclusion window and VINS's own gates.
struct Config {
    /// The pinhole that normalized coordinates are projected through, pixels (VINS: its
    /// `FOCAL_LENGTH`, 460, and the image centre); also the pinhole of undistorted pixel
    /// arrays. topoloc's RANSAC thresholds are in these pixels.
    double fx = 0, fy = 0, cx = 0, cy = 0;
    /// The camera in the body frame (VINS `tic`, `qic`): optical axes z forward, x right, y down.
    /// VINS estimates them online: pass each new estimate to `LoopDetector::set_extrinsics`.
    /// loop_fusion makes its detector before any estimate arrives (its `qic` is then zero): a
    /// `qic` that is no rotation means "not known yet", and keyframes are refused until
    /// `set_extrinsics`.
    Eigen::Vector3d tic = Eigen::Vector3d::Zero();
    Eigen::Matrix3d qic = Eigen::Matrix3d::Identity();
    /// Keyframes whose index is within this many of the new one's are never candidates (VINS
    /// queries DBoW2 with `max_id = index - 50`, strictly below: the old index is at most
    /// `index - 51`).
    uint64_t exclude_recent = 51;
    /// VINS's findConnection gates: |relative yaw| below this, degrees, and |relative_t| below
    /// `max_translation_m`.
    double max_yaw_deg = 30.0;
    double max_translation_m = 20.0;
    /// ORB keypoints extracted from the image when a keyframe brings no points of its own.
    int orb_features = 1000;
    /// topoloc's loop options; the fields above override `fx`..`cy` and `exclude_recent_ids`.
    topoloc::LoopOptions options = topoloc::default_loop_options();
};

/// Yaw (rotation about z) of `R`, degrees, as VINS's `Utility::R2ypr` gives it.
inline double yaw_deg(const Eigen::Matrix3d &R)
{
    return std::atan2(R(1, 0), R(0, 0)) * 180.0 / M_PI;
}

/// `angle` in (-180, 180] degrees.
inline double normalize_deg(double angle)
{
    while (angle > 180.0)
        angle -= 360.0;
    while (angle <= -180.0)
        angle += 360.0;
    return angle;
}

/// The loop detector of a VINS pose graph. Owns a topoloc describer (of the given map) and
/// loop detector; keeps per keyframe only its VIO pose and its accepted hint.
///
/// Errors: VINS does not expect exceptions from its loop detector. A keyframe that cannot be
/// used (index not increasing, a duplicate, a NaN pose, an image of another size, points and
/// descriptors of different lengths, an image without content) makes `detectLoop` return -1,
/// adds nothing, records `last_error()` and calls the logger (if set; an exception it throws is
/// swallowed); no hint is ever built from it. Construction throws `topoloc::Error` (missing
/// model, map without describer).
/// Thread safety: one thread at a time (VINS calls it from its pose-graph thread).
class LoopDetector {
public:
    /// A detector whose keyframe images are described by `describer_map`'s describer (a map
    /// built from images of another run or place: its PCA is never fitted on the run itself).
    LoopDetector(const topoloc::Map &describer_map, const Config &config)
        : config_(config), describer_(describer_map), kind_(describer_map.descriptor_kind()),
          model_(describer_map.descriptor_model()), dim_(describer_map.dim()),
          orb_(cv::ORB::create(config.orb_features))
    {
        config_.options.fx = config.fx;
        config_.options.fy = config.fy;
        config_.options.cx = config.cx;
        config_.options.cy = config.cy;
        config_.options.exclude_recent_ids = config.exclude_recent;
        body_T_camera_.setIdentity();
        extrinsics_known_ =
            config.tic.allFinite() && config.qic.allFinite() && is_rotation(config.qic);
        if (extrinsics_known_) {
            body_T_camera_.linear() = config.qic;
            body_T_camera_.translation() = config.tic;
        }
        clear();
    }

    /// Sets the camera extrinsics for the keyframes added from now on (VINS publishes its online
    /// estimate of `tic`, `qic`; loop_fusion's `extrinsic_callback` receives it). Each keyframe
    /// keeps the extrinsics it was added with. Returns false, logs and keeps the old ones for
    /// a non-finite translation or a matrix that is not a rotation.
    bool set_extrinsics(const Eigen::Vector3d &tic, const Eigen::Matrix3d &qic)
    {
        if (!tic.allFinite() || !qic.allFinite() || !is_rotation(qic)) {
            fail("set_extrinsics: tic must be finite and qic a rotation");
            return false;
        }
        body_T_camera_.linear() = qic;
        body_T_camera_.translation() = tic;
        extrinsics_known_ = true;
        errors_.record("");
        return true;
    }

    /// Sets the function that receives every error message and every refused loop (e.g.
    /// ROS_WARN or spdlog).
    void set_logger(topoloc_adapter::Logger logger) { errors_.set_logger(std::move(logger)); }

    /// The last error message ("" when the last call succeeded).
    std::string last_error() const { return errors_.last_error(); }

    /// Keyframes added since construction or the last `clear`.
    std::size_t size() const noexcept { return added_.size(); }

    /// Forgets every keyframe: a new run starts (new indices may start anywhere).
    void clear()
    {
        detector_ = topoloc::LoopDetector::create(kind_, model_, dim_, config_.options);
        added_.clear();
        last_sequence_.reset();
        loops_.clear();
        confirmed_.clear();
        image_size_.reset();
        last_index_.reset();
        errors_.record("");
    }

    /// VINS's `detectLoop(keyframe, frame_index)`: adds `keyframe` (whose `index` must equal
    /// `frame_index`) and returns the index of the old keyframe of its accepted loop, or -1 (no
    /// loop, a loop refused by VINS's gates, or an error: see `last_error()`). The accepted loop's
    /// `LoopInfo` is then available from `findConnection`.
    int detectLoop(const KeyFrame &keyframe, int frame_index)
    {
        errors_.record("");
        confirmed_.clear();
        if (keyframe.index != frame_index) {
            return fail("keyframe.index " + std::to_string(keyframe.index) +
                        " is not frame_index " + std::to_string(frame_index));
        }
        if (!extrinsics_known_) {
            return fail("keyframe " + std::to_string(keyframe.index) +
                        ": no camera extrinsics yet (Config::qic is no rotation): call "
                        "set_extrinsics from extrinsic_callback");
        }
        std::string why = validate(keyframe);
        if (!why.empty())
            return fail(why);
        topoloc::LoopHint hint;
        try {
            hint = add(keyframe);
        } catch (const std::exception &e) { // topoloc::Error, cv::Exception: nothing was added
            return fail(std::string("keyframe ") + std::to_string(keyframe.index) + ": " +
                        e.what());
        }
        added_[keyframe.index] = Added{origin_pose(keyframe), body_T_camera_};
        last_index_ = keyframe.index;
        last_sequence_ = keyframe.sequence;
        for (const topoloc::LoopHint &earlier : detector_.confirmed()) {
            if (std::optional<LoopInfo> info = accept(earlier))
                confirmed_.push_back(*info);
        }
        const std::optional<LoopInfo> info = hint.accepted ? accept(hint) : std::nullopt;
        return info ? info->old_index : -1;
    }

    /// VINS's `findConnection`: the loop of keyframe `cur_index` with `old_index` as detected,
    /// written to `info`; false when there is none (never for a keyframe `detectLoop` refused).
    bool findConnection(int cur_index, int old_index, LoopInfo &info) const
    {
        const auto found = loops_.find(cur_index);
        if (found == loops_.end() || found->second.old_index != old_index)
            return false;
        info = found->second;
        return true;
    }

    /// What the pose graph writes after `detectLoop(keyframe, cur_index)` returned
    /// `loop_index`, given VINS's `earliest_loop_index` before it (see `PoseGraphUpdate`).
    PoseGraphUpdate pose_graph_update(int cur_index, int loop_index, int earliest_loop_index) const
    {
        PoseGraphUpdate update;
        update.earliest_loop_index = earliest_loop_index;
        LoopInfo current;
        if (loop_index >= 0 && findConnection(cur_index, loop_index, current))
            update.loops.push_back(current);
        update.loops.insert(update.loops.end(), confirmed_.begin(), confirmed_.end());
        for (const LoopInfo &loop : update.loops) {
            if (update.earliest_loop_index < 0 || loop.old_index < update.earliest_loop_index)
                update.earliest_loop_index = loop.old_index;
        }
        if (!update.loops.empty())
            update.optimize_index = cur_index;
        return update;
    }

    /// Loops of earlier keyframes that the last `detectLoop` confirmed (topoloc accepts the first
    /// keyframes of a revisit once a later one completes the consistency streak): the host adds
    /// them to its pose graph as it does the current one's. Replaced by the next `detectLoop`.
    const std::vector<LoopInfo> &confirmed() const noexcept { return confirmed_; }

private:
    using Isometry = Eigen::Isometry3d;

    /// Records and logs an error of the current call; returns detectLoop's "no loop".
    int fail(const std::string &message)
    {
        const std::string error = "topoloc_vins: " + message;
        topoloc_adapter::log(errors_.record(error), error);
        return -1;
    }

    /// Logs a refused loop (not an error of the call).
    void note(const std::string &message) const
    {
        topoloc_adapter::log(errors_.logger(), "topoloc_vins: " + message);
    }

    static bool finite(const Eigen::MatrixXd &m) { return m.allFinite(); }

    static bool is_rotation(const Eigen::Matrix3d &R)
    {
        const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
        return orthogonality <= 1e-6 && R.determinant() > 0;
    }

    /// Why `keyframe` cannot be used, or "".
    std::string validate(const KeyFrame &keyframe) const
    {
        const std::string name = "keyframe " + std::to_string(keyframe.index);
        if (last_index_ && keyframe.index <= *last_index_) {
            return name + " does not follow keyframe " + std::to_string(*last_index_) +
                   (keyframe.index == *last_index_ ? " (duplicate index)" : " (out of order)");
        }
        if (!finite(keyframe.vio_T_w_i) || !finite(keyframe.vio_R_w_i) ||
            !std::isfinite(keyframe.time_stamp)) {
            return name + " has a non-finite pose or timestamp";
        }
        if (!is_rotation(keyframe.vio_R_w_i)) {
            return name + " has a vio_R_w_i that is not a rotation";
        }
        if (keyframe.image.empty() || keyframe.image.depth() != CV_8U ||
            (keyframe.image.channels() != 1 && keyframe.image.channels() != 3)) {
            return name + " needs an 8-bit grey or BGR image";
        }
        const std::string size = image_size_.mismatch(keyframe.image.size(), name + "'s image");
        if (!size.empty()) {
            return size;
        }
        if (keyframe.origin_vio_T.has_value() != keyframe.origin_vio_R.has_value()) {
            return name + ": origin_vio_T and origin_vio_R must be given together";
        }
        if (keyframe.origin_vio_T &&
            (!finite(*keyframe.origin_vio_T) || !finite(*keyframe.origin_vio_R) ||
             !is_rotation(*keyframe.origin_vio_R))) {
            return name + " has a non-finite origin_vio_T or an origin_vio_R that is no rotation";
        }
        const std::size_t points = keyframe.point_3d.size();
        const auto fits = [](std::size_t n, std::size_t expected) {
            return n == 0 || n == expected;
        };
        if (keyframe.window_descriptors.size() != points ||
            !fits(keyframe.point_2d_norm.size(), points) ||
            !fits(keyframe.point_2d_uv.size(), points) ||
            (points > 0 && keyframe.point_2d_norm.empty() && keyframe.point_2d_uv.empty())) {
            return name + ": point_3d, window_descriptors and point_2d_norm or point_2d_uv " +
                   "differ in length";
        }
        const std::size_t extra = keyframe.descriptors.size();
        if (!fits(keyframe.keypoints_norm.size(), extra) ||
            !fits(keyframe.keypoints.size(), extra) ||
            (extra > 0 && keyframe.keypoints_norm.empty() && keyframe.keypoints.empty())) {
            return name + ": keypoints_norm or keypoints and descriptors differ in length";
        }
        return "";
    }

    /// The body pose of a keyframe.
    static Isometry body_pose(const KeyFrame &keyframe)
    {
        Isometry pose = Isometry::Identity();
        pose.linear() = keyframe.vio_R_w_i;
        pose.translation() = keyframe.vio_T_w_i;
        return pose;
    }

    static topoloc::Pose row_major(const Isometry &pose)
    {
        topoloc::Pose out{};
        const Eigen::Matrix4d m = pose.matrix();
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c)
                out[4 * r + c] = m(r, c);
        return out;
    }

    /// Describes and adds `keyframe` to topoloc; returns its hint.
    topoloc::LoopHint add(const KeyFrame &keyframe)
    {
        cv::Mat grey = keyframe.image;
        if (grey.channels() == 3)
            cv::cvtColor(keyframe.image, grey, cv::COLOR_BGR2GRAY);
        if (!grey.isContinuous())
            grey = grey.clone();
        topoloc::LoopKeyframe kf;
        kf.id = static_cast<uint64_t>(keyframe.index);
        kf.timestamp = keyframe.time_stamp;
        kf.descriptor = describer_.describe(topoloc::image_view(
            grey.data, uint32_t(grey.cols), uint32_t(grey.rows), TOPOLOC_PIXEL_GRAY8));
        kf.world_T_body = row_major(body_pose(keyframe));
        kf.body_T_camera = row_major(body_T_camera_);
        if (keyframe.point_3d.empty() && keyframe.descriptors.empty()) {
            add_orb(grey, kf);
        } else {
            add_points(keyframe, (origin_pose(keyframe) * body_T_camera_).inverse(), kf);
        }
        if (last_sequence_ && keyframe.sequence != *last_sequence_)
            detector_.begin_session(); // cannot fail: the keyframe was checked
        topoloc::LoopHint hint = detector_.add(kf);
        image_size_.remember(keyframe.image.size());
        return hint;
    }

    /// The body pose `point_3d` is in: VINS's origin pose, else the VIO pose.
    static Isometry origin_pose(const KeyFrame &keyframe)
    {
        if (!keyframe.origin_vio_T)
            return body_pose(keyframe);
        Isometry pose = Isometry::Identity();
        pose.linear() = *keyframe.origin_vio_R;
        pose.translation() = *keyframe.origin_vio_T;
        return pose;
    }

    /// Point `i` of `norm` (projected through the pinhole) or, without normalized ones, of
    /// `pixels`.
    cv::Point2f pixel(const std::vector<cv::Point2f> &norm, const std::vector<cv::Point2f> &pixels,
                      std::size_t i) const
    {
        if (norm.empty())
            return pixels[i];
        return {float(config_.fx * norm[i].x + config_.cx),
                float(config_.fy * norm[i].y + config_.cy)};
    }

    /// The host's points: tracked ones with their 3D positions (moved into the camera frame),
    /// then the extra keypoints without.
    void add_points(const KeyFrame &keyframe, const Isometry &camera_T_world,
                    topoloc::LoopKeyframe &kf) const
    {
        const float nan = std::numeric_limits<float>::quiet_NaN();
        auto push = [&kf](const cv::Point2f &uv, const Descriptor &d, const Eigen::Vector3f &p) {
            kf.keypoints.insert(kf.keypoints.end(), {uv.x, uv.y});
            kf.keypoint_descriptors.insert(kf.keypoint_descriptors.end(), d.begin(), d.end());
            kf.camera_points.insert(kf.camera_points.end(), {p.x(), p.y(), p.z()});
        };
        for (std::size_t i = 0; i < keyframe.point_3d.size(); ++i) {
            const cv::Point3f &w = keyframe.point_3d[i];
            const Eigen::Vector3d c = camera_T_world * Eigen::Vector3d(w.x, w.y, w.z);
            push(pixel(keyframe.point_2d_norm, keyframe.point_2d_uv, i),
                 keyframe.window_descriptors[i], c.cast<float>());
        }
        for (std::size_t i = 0; i < keyframe.descriptors.size(); ++i) {
            push(pixel(keyframe.keypoints_norm, keyframe.keypoints, i), keyframe.descriptors[i],
                 Eigen::Vector3f(nan, nan, nan));
        }
    }

    /// ORB keypoints of the image, without 3D points (hints matched to this keyframe then carry
    /// a translation direction only, which `accept` refuses: VINS needs metric loops).
    void add_orb(const cv::Mat &grey, topoloc::LoopKeyframe &kf)
    {
        std::vector<cv::KeyPoint> keypoints;
        cv::Mat descriptors;
        orb_->detectAndCompute(grey, cv::noArray(), keypoints, descriptors);
        for (std::size_t i = 0; i < keypoints.size(); ++i) {
            kf.keypoints.insert(kf.keypoints.end(), {keypoints[i].pt.x, keypoints[i].pt.y});
            const uint8_t *row = descriptors.ptr<uint8_t>(int(i));
            kf.keypoint_descriptors.insert(kf.keypoint_descriptors.end(), row, row + 32);
        }
    }

    /// The `LoopInfo` of an accepted hint when it passes VINS's gates (metric, yaw, translation);
    /// recorded for `findConnection`. Refusals are logged.
    std::optional<LoopInfo> accept(const topoloc::LoopHint &hint)
    {
        const int cur = int(hint.query_id), old = int(hint.matched_id);
        if (!hint.has_pose || !hint.scale_known) {
            note("loop " + std::to_string(cur) + " -> " + std::to_string(old) +
                 (hint.has_pose ? " has a translation direction only (PnP with the 3D points "
                                  "found too few inliers, or there were none)"
                                : " has no pose") +
                 "; not a VINS loop");
            return std::nullopt;
        }
        Eigen::Matrix4d m;
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c)
                m(r, c) = hint.matched_T_query[4 * r + c];
        const Isometry camera_old_T_cur(m);
        const Added &current = added_.at(cur);
        const auto old_entry = added_.find(old);
        const Isometry &old_body_T_camera =
            old_entry != added_.end() ? old_entry->second.body_T_camera : current.body_T_camera;
        const Isometry relative =
            old_body_T_camera * camera_old_T_cur * current.body_T_camera.inverse();
        LoopInfo info;
        info.cur_index = cur;
        info.old_index = old;
        info.relative_t = relative.translation();
        info.relative_q = Eigen::Quaterniond(relative.linear()).normalized();
        const Eigen::Matrix3d R_cur = current.body.linear();
        info.relative_yaw =
            normalize_deg(yaw_deg(R_cur) - yaw_deg(R_cur * relative.linear().transpose()));
        info.inliers = hint.inliers;
        info.covariance = body_covariance(hint, current.body_T_camera);
        if (std::abs(info.relative_yaw) >= config_.max_yaw_deg ||
            info.relative_t.norm() >= config_.max_translation_m) {
            note("loop " + std::to_string(cur) + " -> " + std::to_string(old) +
                 " refused by VINS's gates (yaw " + std::to_string(info.relative_yaw) +
                 " deg, |t| " + std::to_string(info.relative_t.norm()) + " m)");
            return std::nullopt;
        }
        loops_[cur] = info;
        return info;
    }

    /// The hint's covariance (camera frames, right perturbation) in the body frames: the
    /// adjoint of `camera_T_body` (the current keyframe's extrinsics) maps a camera-frame
    /// tangent to the body frame's.
    static Eigen::Matrix<double, 6, 6> body_covariance(const topoloc::LoopHint &hint,
                                                       const Isometry &body_T_camera)
    {
        Eigen::Matrix<double, 6, 6> camera;
        for (int r = 0; r < 6; ++r)
            for (int c = 0; c < 6; ++c)
                camera(r, c) = hint.covariance[6 * r + c];
        // A right perturbation exp(xi) of camera_old_T_cur is one of body_old_T_cur by
        // Ad(body_T_camera) xi; rotation first: [R 0; [t]x R R].
        const Eigen::Matrix3d R = body_T_camera.linear();
        const Eigen::Vector3d t = body_T_camera.translation();
        Eigen::Matrix3d tx;
        tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
        Eigen::Matrix<double, 6, 6> adjoint = Eigen::Matrix<double, 6, 6>::Zero();
        adjoint.topLeftCorner<3, 3>() = R;
        adjoint.bottomLeftCorner<3, 3>() = tx * R;
        adjoint.bottomRightCorner<3, 3>() = R;
        return adjoint * camera * adjoint.transpose();
    }

    Config config_;
    topoloc::Describer describer_;
    std::string kind_, model_;
    uint32_t dim_;
    cv::Ptr<cv::ORB> orb_;
    Isometry body_T_camera_;
    bool extrinsics_known_ = false; // a rotation was given (Config or set_extrinsics)
    topoloc::LoopDetector detector_;
    /// What the adapter keeps of an added keyframe: its body pose at creation (VINS's origin
    /// pose, whose yaw its `relative_yaw` uses) and its extrinsics.
    struct Added {
        Isometry body;
        Isometry body_T_camera;
    };
    std::map<int, Added> added_;
    std::optional<int> last_sequence_;
    std::map<int, LoopInfo> loops_;
    std::vector<LoopInfo> confirmed_;
    topoloc_adapter::ImageSize image_size_;
    std::optional<int> last_index_;
    topoloc_adapter::ErrorReport errors_;
};

} // namespace topoloc_vins

#endif // TOPOLOC_VINS_HPP
