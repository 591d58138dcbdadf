// Drift correction the ORB-SLAM way: keyframes of a generated sequence (drifting odometry,
// images, depth, ground truth from `topoloc simulate --depth`) go through the ORB-SLAM
// `KeyFrameDatabase` adapter (topoloc_orbslam.hpp) as ORB-SLAM3's loop closing thread uses it
// (`DetectNBestCandidates` for the new keyframe, then `add`); the accepted loops, with the
// relative pose and covariance of their hints, and the odometry feed an SE3 pose graph
// (rotation and position per keyframe) solved with Ceres, as ORB-SLAM's essential-graph
// optimisation does with g2o. Prints the ATE RMSE (Sim3 Umeyama alignment) of the raw odometry
// and of the corrected trajectory, the loops used and how many of them were false (judged
// against ground truth after the fact), and writes a PNG of the trajectories.
//
//   orbslam_drift_demo --sequence SIM/traj-000 --describer MAP [--out PNG] [--json]
//                      [--max-keyframes N] [--exclude-recent N] [--orb-features N]
//                      [--fast-threshold N] [--clahe CLIP]
//
// The host here is a stand-in for ORB-SLAM: keyframes and map points with the members the
// adapter's `DefaultAccess` reads (ORB-SLAM2's shapes), every frame a keyframe, map points
// from the depth image placed in the odometry's world (ORB-SLAM's map points live in its
// world), and the camera pose `Tcw = (world_T_body * body_T_camera)^-1` (ORB-SLAM's body is
// its camera; the simulator's body is x forward, z up). Command line, front end, odometry
// sigmas, the solve that drops inconsistent loops, the judgement and the report are
// cpp-examples/common/demo.hpp's, shared with the VINS demo.
#include "topoloc_orbslam.hpp"

#include "../common/demo.hpp"
#include "../common/sim_sequence.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <optional>
#include <set>

namespace {

namespace host { // stand-ins of ORB-SLAM2's classes: the members DefaultAccess reads

/// ORB-SLAM's `MapPoint`: a world position (3x1 CV_32F, `GetWorldPos()`).
struct MapPoint {
    cv::Mat world; ///< The position in ORB-SLAM's (here: the odometry's) world.

    /// The world position, as ORB-SLAM2 returns it (a copy).
    cv::Mat GetWorldPos() { return world.clone(); }
    /// Never culled here.
    bool isBad() { return false; }
};

/// ORB-SLAM's `KeyFrame`: id, time, undistorted keypoints and their descriptors, the pose
/// `Tcw`, the map point of each keypoint, and the grey image the integration adds (README.md).
struct KeyFrame {
    unsigned long mnId = 0;
    double mTimeStamp = 0.0;
    std::vector<cv::KeyPoint> mvKeysUn;
    cv::Mat mDescriptors;                 ///< N x 32 CV_8U, row i = keypoint i.
    cv::Mat mImGray;                      ///< Freed by the adapter once the keyframe is in topoloc.
    cv::Mat Tcw;                          ///< World to camera, 4x4 CV_32F.
    std::vector<MapPoint *> mvpMapPoints; ///< One per keypoint, null where none.
    float fx = 0, fy = 0, cx = 0, cy = 0; ///< The pinhole of `mvKeysUn`.

    /// `Tcw`, as ORB-SLAM2 returns it (a copy).
    cv::Mat GetPose() { return Tcw.clone(); }
    /// No covisibility graph here: nothing is connected.
    std::set<KeyFrame *> GetConnectedKeyFrames() { return {}; }
    /// The map point of each keypoint.
    std::vector<MapPoint *> GetMapPointMatches() { return mvpMapPoints; }
    /// Never culled here (every frame is kept as a keyframe).
    bool isBad() { return false; }
};

/// ORB-SLAM's `Frame` (relocalization only, unused here).
struct Frame {
    cv::Mat mImGray;
};

} // namespace host

using Database = topoloc_orbslam::KeyFrameDatabase<host::KeyFrame, host::Frame>;
using Match = Database::Match;

/// `T` as a pose of sim_sequence.hpp.
sim::Pose to_sim(const topoloc_orbslam::Pose &T)
{
    sim::Pose p;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c)
            p.R(r, c) = T[std::size_t(4 * r + c)];
        p.t[r] = T[std::size_t(4 * r + 3)];
    }
    return p;
}

/// `p` as a 4x4 row-major pose of the adapter.
topoloc_orbslam::Pose to_adapter(const sim::Pose &p)
{
    topoloc_orbslam::Pose T{0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c)
            T[std::size_t(4 * r + c)] = p.R(r, c);
        T[std::size_t(4 * r + 3)] = p.t[r];
    }
    return T;
}

/// `a * b`.
sim::Pose compose(const sim::Pose &a, const sim::Pose &b)
{
    sim::Pose p;
    p.R = a.R * b.R;
    p.t = a.R * b.t + a.t;
    return p;
}

/// `p^-1`.
sim::Pose inverse(const sim::Pose &p)
{
    sim::Pose q;
    q.R = p.R.transpose();
    q.t = -(q.R * p.t);
    return q;
}

/// An accepted loop of the adapter in body frames: `relative` is `body_old_T_body_cur` and
/// `covariance` its covariance (right perturbation, rotation then translation, body frame).
struct Loop : demo::Loop {
    Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

/// The body-frame loop of an accepted hint, or nothing when the hint carries no metric pose
/// (the matched keyframe had no map points) or its matched keyframe is gone: the pose graph
/// needs a metric relative pose.
std::optional<Loop> body_loop(const Match &m)
{
    if (!m.accepted || !m.has_pose || !m.scale_known || m.query == nullptr ||
        m.matched == nullptr) {
        return std::nullopt;
    }
    const sim::Pose body_T_camera = sim::body_T_camera();
    Loop loop;
    loop.old_index = std::size_t(m.matched->mnId);
    loop.cur_index = std::size_t(m.query->mnId);
    // camera_old_T_camera_cur, moved to the bodies: b_T_c * (c_old_T_c_cur) * c_T_b.
    loop.relative =
        compose(compose(body_T_camera, to_sim(m.matched_T_query)), inverse(body_T_camera));
    Eigen::Matrix<double, 6, 6> camera;
    for (int r = 0; r < 6; ++r)
        for (int c = 0; c < 6; ++c)
            camera(r, c) = m.covariance[std::size_t(6 * r + c)];
    // A right perturbation xi of camera_old_T_cur is Ad(body_T_camera) xi of body_old_T_cur.
    const Eigen::Matrix<double, 6, 6> ad = demo::adjoint(body_T_camera);
    loop.covariance = ad * camera * ad.transpose();
    return loop;
}

/// The square root of the information of a loop edge: per-axis sigmas, the square roots of
/// the body-frame covariance's diagonal (as the VINS demo) raised to the floors of demo.hpp.
/// The full matrix was tried on train_1_night: it let in a loop 5.7 degrees off the truth.
Eigen::Matrix<double, 6, 6> loop_sqrt_information(const Eigen::Matrix<double, 6, 6> &covariance)
{
    Eigen::Matrix<double, 6, 1> inverse_sigma;
    for (int k = 0; k < 6; ++k) {
        const double floor = k < 3 ? demo::kLoopSigmaMinRotDeg * M_PI / 180 : demo::kLoopSigmaMinM;
        inverse_sigma[k] = 1 / std::max(std::sqrt(std::max(covariance(k, k), 0.0)), floor);
    }
    return Eigen::Matrix<double, 6, 6>(inverse_sigma.asDiagonal());
}

/// One SE3 edge i -> j: `T_i^-1 T_j` should be `relative`. The residual is the right
/// perturbation taking `relative` to it (rotation as an angle-axis vector, then translation,
/// to first order), multiplied by `sqrt_information`.
struct Se3Edge {
    Eigen::Quaterniond relative_q;
    Eigen::Vector3d relative_t;
    Eigen::Matrix<double, 6, 6> sqrt_information;

    /// The whitened residual of the poses (q_i, t_i) and (q_j, t_j).
    template <typename T>
    bool operator()(const T *q_i, const T *t_i, const T *q_j, const T *t_j, T *residual) const
    {
        const Eigen::Map<const Eigen::Quaternion<T>> qi(q_i), qj(q_j);
        const Eigen::Map<const Eigen::Matrix<T, 3, 1>> ti(t_i), tj(t_j);
        const Eigen::Quaternion<T> q_ij = qi.conjugate() * qj;
        const Eigen::Matrix<T, 3, 1> t_ij = qi.conjugate() * (tj - ti);
        const Eigen::Quaternion<T> measured_inv = relative_q.conjugate().cast<T>();
        const Eigen::Quaternion<T> dq = measured_inv * q_ij;
        const T wxyz[4] = {dq.w(), dq.x(), dq.y(), dq.z()};
        Eigen::Matrix<T, 6, 1> e;
        ceres::QuaternionToAngleAxis(wxyz, e.data());
        e.template tail<3>() = measured_inv * (t_ij - relative_t.cast<T>());
        Eigen::Map<Eigen::Matrix<T, 6, 1>> out(residual);
        out = sqrt_information.cast<T>() * e;
        return true;
    }

    /// The Ceres cost of an edge (automatic derivatives).
    static ceres::CostFunction *create(const sim::Pose &relative,
                                       const Eigen::Matrix<double, 6, 6> &sqrt_information)
    {
        return new ceres::AutoDiffCostFunction<Se3Edge, 6, 4, 3, 4, 3>(
            new Se3Edge{Eigen::Quaterniond(relative.R).normalized(), relative.t, sqrt_information});
    }
};

/// The pose graph's unknowns: per keyframe a unit quaternion (Eigen's x y z w) and a position.
struct Graph {
    std::vector<std::array<double, 4>> q;
    std::vector<std::array<double, 3>> t;

    /// The unknowns' initial values: `poses` (the odometry).
    explicit Graph(const std::vector<sim::Pose> &poses)
    {
        for (const sim::Pose &p : poses) {
            const Eigen::Quaterniond r = Eigen::Quaterniond(p.R).normalized();
            q.push_back({r.x(), r.y(), r.z(), r.w()});
            t.push_back({p.t.x(), p.t.y(), p.t.z()});
        }
    }

    /// Adds the edge i -> j to `problem`; returns its block.
    ceres::ResidualBlockId add(ceres::Problem &problem, ceres::CostFunction *cost,
                               ceres::LossFunction *loss, std::size_t i, std::size_t j)
    {
        return problem.AddResidualBlock(cost, loss, q[i].data(), t[i].data(), q[j].data(),
                                        t[j].data());
    }

    /// The odometry edge i -> j (see demo::solve_pose_graph).
    void add_odometry(ceres::Problem &problem, std::size_t i, std::size_t j,
                      const sim::Pose &relative, double sigma_t, double sigma_rot)
    {
        Eigen::Matrix<double, 6, 1> inverse_sigma;
        inverse_sigma << Eigen::Vector3d::Constant(1 / sigma_rot),
            Eigen::Vector3d::Constant(1 / sigma_t);
        add(problem,
            Se3Edge::create(relative, Eigen::Matrix<double, 6, 6>(inverse_sigma.asDiagonal())),
            nullptr, i, j);
    }

    /// The edge of `loop`, with a Huber loss; returns its block.
    ceres::ResidualBlockId add_loop(ceres::Problem &problem, const Loop &loop)
    {
        return add(problem, Se3Edge::create(loop.relative, loop_sqrt_information(loop.covariance)),
                   new ceres::HuberLoss(1.0), loop.old_index, loop.cur_index);
    }

    /// Unit quaternions; the first pose fixed.
    void fix_gauge(ceres::Problem &problem)
    {
        for (std::array<double, 4> &r : q)
            problem.SetManifold(r.data(), new ceres::EigenQuaternionManifold);
        problem.SetParameterBlockConstant(q[0].data());
        problem.SetParameterBlockConstant(t[0].data());
    }

    /// Keyframe `i`'s pose as the graph has it.
    sim::Pose pose(std::size_t i) const
    {
        sim::Pose p;
        p.R =
            Eigen::Quaterniond(q[i][3], q[i][0], q[i][1], q[i][2]).normalized().toRotationMatrix();
        p.t = Eigen::Vector3d(t[i][0], t[i][1], t[i][2]);
        return p;
    }
};

/// Builds and solves the SE3 graph (odometry edges, loop edges with a Huber loss, the first
/// pose fixed) with demo::solve_pose_graph, dropping loop edges inconsistent with the rest
/// (chi-square of 6 degrees of freedom). Returns the corrected poses.
std::vector<sim::Pose> optimise(const std::vector<sim::Pose> &odometry, std::vector<Loop> &loops)
{
    return demo::solve_pose_graph<Graph>(odometry, loops, demo::kChi2Dof6);
}

/// The stand-in ORB-SLAM's keyframes and map points (stable addresses, as ORB-SLAM's
/// heap-allocated ones: the database keeps pointers).
struct Host {
    std::deque<host::KeyFrame> keyframes;
    std::deque<host::MapPoint> points;

    /// Keyframe `i` of `seq` with the odometry pose `world_T_body`: its grey image, the front
    /// end's features, and a map point (in the world) for each feature with depth.
    host::KeyFrame *make(const sim::Sequence &seq, std::size_t i, const sim::Pose &world_T_body,
                         demo::FrontEnd &front_end)
    {
        host::KeyFrame &kf = keyframes.emplace_back();
        kf.mnId = i;
        kf.mTimeStamp = seq.stamps[i];
        kf.mImGray = seq.grey(i);
        const sim::Features f = front_end(seq, i, kf.mImGray);
        kf.mvKeysUn = f.keypoints; // the simulator's images have no distortion
        kf.fx = float(seq.intrinsics.fx);
        kf.fy = float(seq.intrinsics.fy);
        kf.cx = float(seq.intrinsics.cx);
        kf.cy = float(seq.intrinsics.cy);
        kf.mDescriptors = f.descriptors;
        const sim::Pose world_T_camera = compose(world_T_body, sim::body_T_camera());
        kf.Tcw = topoloc_orbslam::to_mat(to_adapter(inverse(world_T_camera)));
        for (const Eigen::Vector3d &c : f.camera_points) {
            if (!c.allFinite()) {
                kf.mvpMapPoints.push_back(nullptr);
                continue;
            }
            const Eigen::Vector3d w = world_T_camera.R * c + world_T_camera.t;
            host::MapPoint &mp = points.emplace_back();
            mp.world = (cv::Mat_<float>(3, 1) << float(w.x()), float(w.y()), float(w.z()));
            kf.mvpMapPoints.push_back(&mp);
        }
        return &kf;
    }
};

/// Throws the database's error of the last call, if any.
void check(const Database &db)
{
    const std::string error = db.last_error();
    if (!error.empty())
        throw std::runtime_error("topoloc_orbslam: " + error);
}

/// The experiment: every frame an ORB-SLAM keyframe through the database, then the pose graph
/// and the report.
void run(const demo::Args &args)
{
    const sim::Sequence seq(args.sequence);
    const topoloc::Map describer_map = topoloc::Map::load(args.describer);
    topoloc::LoopOptions options = topoloc::default_loop_options();
    options.exclude_recent_ids = args.exclude_recent;
    // The adapter's README sets consistent_keyframes = 1 because ORB-SLAM's LoopClosing checks
    // consistency itself; this host has no such check, so topoloc's default streak stays.
    Database db(describer_map, options); // the intrinsics come with each keyframe

    demo::FrontEnd front_end(args);
    const std::size_t n = demo::keyframe_count(args, seq);
    const std::vector<sim::Pose> odometry(seq.odometry.begin(), seq.odometry.begin() + long(n));
    Host slam;
    std::vector<Loop> loops;
    std::size_t refused = 0; // accepted hints without a metric pose: no edge for the graph
    auto collect = [&](const Match &m) {
        if (std::optional<Loop> loop = body_loop(m))
            loops.push_back(*loop);
        else
            ++refused;
    };
    demo::Timings timings;
    for (std::size_t i = 0; i < n; ++i) {
        host::KeyFrame *kf = slam.make(seq, i, odometry[i], front_end);
        std::vector<host::KeyFrame *> loop_candidates, merge_candidates;
        timings.measure([&] {
            // ORB-SLAM3's LoopClosing: query the new keyframe first, then add it (a no-op now).
            db.DetectNBestCandidates(kf, loop_candidates, merge_candidates, 3);
            check(db);
            db.add(kf);
            check(db);
        });
        for (const Match &earlier : db.TakeConfirmed())
            collect(earlier);
        check(db);
        if (!loop_candidates.empty()) {
            const std::optional<Match> hint = db.GetHint(kf);
            check(db);
            if (hint && hint->matched == loop_candidates.front())
                collect(*hint);
        }
    }

    const std::vector<sim::Pose> corrected = optimise(odometry, loops);
    demo::report(args, seq, odometry, corrected, loops, refused, timings,
                 {"the host (no metric pose)", "SE3", "DetectNBestCandidates + add"});
}

} // namespace

int main(int argc, char **argv) { return demo::run("orbslam_drift_demo", argc, argv, run); }
