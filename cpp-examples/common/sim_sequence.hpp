// What the drift-correction demos share: reading a sequence written by `topoloc simulate
// --depth` (images, depth, drifting odometry, ground truth, intrinsics), playing the SLAM host's
// front end on it (ORB keypoints with their depth-image 3D points, as a VIO or ORB-SLAM front
// end has them), judging trajectories with topoloc's evo-equivalent metrics, and drawing them.
//
// Not part of the adapters: a host brings its own front end and its own trajectories.
#ifndef TOPOLOC_EXAMPLES_SIM_SEQUENCE_HPP
#define TOPOLOC_EXAMPLES_SIM_SEQUENCE_HPP

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "topoloc.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace sim {

/// A rigid pose `world_T_body`: rotation and translation.
struct Pose {
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    Eigen::Vector3d t = Eigen::Vector3d::Zero();

    /// The pose of a TUM row's `tx ty tz qx qy qz qw`.
    static Pose from_tum(const std::array<double, 7> &v)
    {
        Pose p;
        p.t = Eigen::Vector3d(v[0], v[1], v[2]);
        p.R = Eigen::Quaterniond(v[6], v[3], v[4], v[5]).normalized().toRotationMatrix();
        return p;
    }

    /// `a^-1 * b`: `b` in `a`'s frame.
    static Pose between(const Pose &a, const Pose &b)
    {
        Pose p;
        p.R = a.R.transpose() * b.R;
        p.t = a.R.transpose() * (b.t - a.t);
        return p;
    }

    /// A TUM pose record at `timestamp`.
    topoloc::TimedPose timed(double timestamp) const
    {
        const Eigen::Quaterniond q(R);
        topoloc::TimedPose out;
        out.timestamp = timestamp;
        out.pose = {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
        return out;
    }
};

/// A TUM trajectory file: timestamps and poses. Throws `std::runtime_error` naming the line of
/// a malformed record.
inline void read_tum(const std::string &path, std::vector<double> &stamps, std::vector<Pose> &poses)
{
    std::ifstream in(path);
    if (!in)
        throw std::runtime_error("cannot read " + path);
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
        if (line.empty() || line[0] == '#')
            continue;
        std::istringstream fields(line);
        double t = 0;
        std::array<double, 7> v{};
        fields >> t;
        for (double &x : v)
            fields >> x;
        if (!fields)
            throw std::runtime_error(path + ":" + std::to_string(number) + ": not a TUM record");
        stamps.push_back(t);
        poses.push_back(Pose::from_tum(v));
    }
}

/// Pinhole intrinsics, pixels.
struct Intrinsics {
    double fx = 0, fy = 0, cx = 0, cy = 0;
};

/// The value of `"key": number` in a small flat JSON object (intrinsics.json).
inline double json_number(const std::string &text, const std::string &key, const std::string &path)
{
    const std::size_t at = text.find("\"" + key + "\"");
    const std::size_t colon = at == std::string::npos ? at : text.find(':', at);
    if (colon == std::string::npos)
        throw std::runtime_error(path + " has no \"" + key + "\"");
    return std::stod(text.substr(colon + 1));
}

/// One sequence of `topoloc simulate --depth` (a `traj-00i` folder).
struct Sequence {
    std::string dir;
    Intrinsics intrinsics;
    std::vector<double> stamps; ///< Frame times (the odometry's).
    std::vector<Pose> odometry; ///< Drifting `world_T_body`, body x forward, z up.
    std::vector<Pose> truth;    ///< Ground-truth `world_T_body`.

    /// Reads `dir`; throws `std::runtime_error` on a missing or inconsistent file.
    explicit Sequence(const std::string &folder) : dir(folder)
    {
        std::ifstream in(dir + "/intrinsics.json");
        if (!in)
            throw std::runtime_error("cannot read " + dir + "/intrinsics.json");
        const std::string text((std::istreambuf_iterator<char>(in)),
                               std::istreambuf_iterator<char>());
        const std::string path = dir + "/intrinsics.json";
        intrinsics = {json_number(text, "fx", path), json_number(text, "fy", path),
                      json_number(text, "cx", path), json_number(text, "cy", path)};
        read_tum(dir + "/odometry.txt", stamps, odometry);
        std::vector<double> truth_stamps;
        read_tum(dir + "/groundtruth.txt", truth_stamps, truth);
        if (truth_stamps != stamps) {
            throw std::runtime_error(dir + ": odometry and ground truth have different timestamps");
        }
    }

    std::size_t size() const { return stamps.size(); }

    /// Frame `i`'s file name (`000042.png`).
    static std::string file(std::size_t i)
    {
        char name[32];
        std::snprintf(name, sizeof name, "%06zu.png", i);
        return name;
    }

    /// Frame `i`'s grey image; throws when it cannot be read.
    cv::Mat grey(std::size_t i) const
    {
        cv::Mat image = cv::imread(dir + "/images/" + file(i), cv::IMREAD_GRAYSCALE);
        if (image.empty())
            throw std::runtime_error("cannot read " + dir + "/images/" + file(i));
        return image;
    }

    /// Frame `i`'s depth image (16-bit millimetres, 0 = none); throws when it cannot be read.
    cv::Mat depth(std::size_t i) const
    {
        cv::Mat image = cv::imread(dir + "/depth/" + file(i), cv::IMREAD_UNCHANGED);
        if (image.empty() || image.type() != CV_16UC1) {
            throw std::runtime_error(dir + "/depth/" + file(i) + " is not a 16-bit depth image");
        }
        return image;
    }
};

/// The optical camera (z forward, x right, y down) in the simulator's body (x forward, z up).
inline Pose body_T_camera()
{
    Pose p;
    p.R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    return p;
}

/// A host front end's view of one keyframe: ORB keypoints, their descriptors and, where the
/// depth image has them, their 3D points in the camera frame (NaN otherwise).
struct Features {
    std::vector<cv::KeyPoint> keypoints;
    cv::Mat descriptors; ///< N x 32, CV_8U.
    std::vector<Eigen::Vector3d> camera_points;
};

/// ORB features of `grey` with their depth points; `clahe` (if set) equalises the image first,
/// as front ends do for dark scenes.
inline Features extract(cv::ORB &orb, const cv::Mat &grey, const cv::Mat &depth,
                        const Intrinsics &k, cv::CLAHE *clahe = nullptr)
{
    Features f;
    cv::Mat input = grey;
    if (clahe != nullptr)
        clahe->apply(grey, input);
    orb.detectAndCompute(input, cv::noArray(), f.keypoints, f.descriptors);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (const cv::KeyPoint &kp : f.keypoints) {
        const int u = cvRound(kp.pt.x), v = cvRound(kp.pt.y);
        const bool inside = u >= 0 && v >= 0 && u < depth.cols && v < depth.rows;
        const double z = inside ? depth.at<uint16_t>(v, u) / 1000.0 : 0.0;
        f.camera_points.push_back(
            z > 0 ? Eigen::Vector3d((kp.pt.x - k.cx) * z / k.fx, (kp.pt.y - k.cy) * z / k.fy, z)
                  : Eigen::Vector3d(nan, nan, nan));
    }
    return f;
}

/// ATE of `poses` (the first frames of the sequence) against the sequence's ground truth after
/// `alignment` (a `TOPOLOC_ALIGN_*`), computed by topoloc's evo-equivalent metrics. Throws
/// `topoloc::Error` (`TOPOLOC_ERR_INVALID_ARGUMENT` for positions too degenerate to align).
inline topoloc::TrajectoryReport ate(const Sequence &seq, const std::vector<Pose> &poses,
                                     uint32_t alignment)
{
    std::vector<topoloc::TimedPose> est, ref;
    for (std::size_t i = 0; i < poses.size(); ++i) {
        est.push_back(poses[i].timed(seq.stamps[i]));
        ref.push_back(seq.truth[i].timed(seq.stamps[i]));
    }
    topoloc::TrajectoryOptions options = topoloc::default_trajectory_options();
    options.alignment = alignment;
    return topoloc::evaluate_trajectory(ref, est, options);
}

/// ATE of `poses` against the sequence's ground truth after a Sim3 (Umeyama) alignment, the
/// seed's chapter 3 definition.
inline topoloc::TrajectoryReport ate_sim3(const Sequence &seq, const std::vector<Pose> &poses)
{
    return ate(seq, poses, TOPOLOC_ALIGN_SIM3);
}

/// `p` moved by the report's alignment (`scale * R p + t`).
inline Eigen::Vector3d aligned(const topoloc::TrajectoryReport &r, const Eigen::Vector3d &p)
{
    Eigen::Matrix3d R;
    R << r.alignment[0], r.alignment[1], r.alignment[2], r.alignment[4], r.alignment[5],
        r.alignment[6], r.alignment[8], r.alignment[9], r.alignment[10];
    return r.scale * R * p + Eigen::Vector3d(r.alignment[3], r.alignment[7], r.alignment[11]);
}

/// A loop edge to draw: the two keyframes' indices.
using Edge = std::pair<std::size_t, std::size_t>;

/// Writes a top view (x right, y up) of the ground truth (green), the raw odometry (red) and
/// the corrected trajectory (blue), each estimate aligned as its report says, with the loop
/// edges (grey) on the corrected one. Throws when the PNG cannot be written.
inline void plot(const std::string &path, const Sequence &seq, const std::vector<Pose> &raw,
                 const topoloc::TrajectoryReport &raw_report, const std::vector<Pose> &corrected,
                 const topoloc::TrajectoryReport &corrected_report, const std::vector<Edge> &loops)
{
    std::vector<std::vector<Eigen::Vector3d>> tracks(3);
    for (std::size_t i = 0; i < seq.size(); ++i) {
        tracks[0].push_back(seq.truth[i].t);
        tracks[1].push_back(aligned(raw_report, raw[i].t));
        tracks[2].push_back(aligned(corrected_report, corrected[i].t));
    }
    Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
    for (const auto &track : tracks)
        for (const Eigen::Vector3d &p : track) {
            lo = lo.cwiseMin(p.head<2>());
            hi = hi.cwiseMax(p.head<2>());
        }
    const int size = 800, margin = 20;
    const double scale = (size - 2 * margin) / std::max((hi - lo).maxCoeff(), 1e-6);
    auto pixel = [&](const Eigen::Vector3d &p) {
        return cv::Point(margin + int((p.x() - lo.x()) * scale),
                         size - margin - int((p.y() - lo.y()) * scale));
    };
    cv::Mat canvas(size, size, CV_8UC3, cv::Scalar(255, 255, 255));
    for (const Edge &e : loops) {
        cv::line(canvas, pixel(tracks[2][e.first]), pixel(tracks[2][e.second]),
                 cv::Scalar(160, 160, 160), 1);
    }
    const std::array<cv::Scalar, 3> colours{cv::Scalar(0, 160, 0), cv::Scalar(0, 0, 220),
                                            cv::Scalar(220, 60, 0)};
    const std::array<const char *, 3> names{"ground truth", "raw odometry", "corrected"};
    for (std::size_t k = 0; k < tracks.size(); ++k) {
        for (std::size_t i = 1; i < tracks[k].size(); ++i) {
            cv::line(canvas, pixel(tracks[k][i - 1]), pixel(tracks[k][i]), colours[k], 2);
        }
        cv::putText(canvas, names[k], cv::Point(margin, margin + 18 * int(k + 1)),
                    cv::FONT_HERSHEY_SIMPLEX, 0.5, colours[k], 1);
    }
    if (!cv::imwrite(path, canvas))
        throw std::runtime_error("cannot write " + path);
}

} // namespace sim

#endif // TOPOLOC_EXAMPLES_SIM_SEQUENCE_HPP
