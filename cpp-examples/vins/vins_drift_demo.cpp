// Drift correction the VINS-Fusion way: keyframes of a generated sequence (drifting odometry,
// images, depth, ground truth from `topoloc simulate --depth`) go through the VINS adapter
// (topoloc_vins.hpp); its loops and the odometry feed a 4-DoF pose graph (x, y, z, yaw per
// keyframe; roll and pitch from the odometry) solved with Ceres, as loop_fusion's optimize4DoF
// does. Prints the ATE RMSE (Sim3 Umeyama alignment) of the raw odometry and of the corrected
// trajectory, the loops used and how many of them were false (judged against ground truth
// after the fact), and writes a PNG of the trajectories.
//
//   vins_drift_demo --sequence SIM/traj-000 --describer MAP [--out PNG] [--json]
//                   [--max-keyframes N] [--exclude-recent N] [--orb-features N]
//                   [--fast-threshold N] [--clahe CLIP]
//
// Command line, front end, odometry sigmas, the solve that drops inconsistent loops, the
// judgement and the report are cpp-examples/common/demo.hpp's, shared with the ORB-SLAM demo.
#include "topoloc_vins.hpp"

#include "../common/demo.hpp"
#include "../common/sim_sequence.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <cmath>

namespace {

/// Yaw, pitch, roll (radians) of `R = Rz(yaw) Ry(pitch) Rx(roll)`.
Eigen::Vector3d ypr(const Eigen::Matrix3d &R)
{
    return {std::atan2(R(1, 0), R(0, 0)), std::asin(-std::clamp(R(2, 0), -1.0, 1.0)),
            std::atan2(R(2, 1), R(2, 2))};
}

/// `Rz(yaw) Ry(pitch) Rx(roll)`, with the yaw an unknown of the graph.
template <typename T> Eigen::Matrix<T, 3, 3> rotation(T yaw, double pitch, double roll)
{
    return (Eigen::AngleAxis<T>(yaw, Eigen::Matrix<T, 3, 1>::UnitZ()) *
            Eigen::AngleAxis<T>(T(pitch), Eigen::Matrix<T, 3, 1>::UnitY()) *
            Eigen::AngleAxis<T>(T(roll), Eigen::Matrix<T, 3, 1>::UnitX()))
        .toRotationMatrix();
}

/// One 4-DoF edge i -> j: `R_i^T (t_j - t_i)` should be `relative_t` and `yaw_j - yaw_i` should
/// be `relative_yaw`, with the pitch and roll of i fixed; residuals divided by their sigmas.
struct FourDofEdge {
    Eigen::Vector3d relative_t;
    double relative_yaw, pitch_i, roll_i;
    Eigen::Vector3d sigma_t;
    double sigma_yaw;

    /// The whitened residual of positions and yaws of i and j.
    template <typename T>
    bool operator()(const T *t_i, const T *yaw_i, const T *t_j, const T *yaw_j, T *residual) const
    {
        const Eigen::Matrix<T, 3, 1> ti(t_i[0], t_i[1], t_i[2]), tj(t_j[0], t_j[1], t_j[2]);
        const Eigen::Matrix<T, 3, 1> local =
            rotation(yaw_i[0], pitch_i, roll_i).transpose() * (tj - ti);
        for (int k = 0; k < 3; ++k)
            residual[k] = (local[k] - T(relative_t[k])) / T(sigma_t[k]);
        T angle = yaw_j[0] - yaw_i[0] - T(relative_yaw);
        angle = ceres::atan2(ceres::sin(angle), ceres::cos(angle));
        residual[3] = angle / T(sigma_yaw);
        return true;
    }

    /// The Ceres cost of `edge` (automatic derivatives).
    static ceres::CostFunction *create(const FourDofEdge &edge)
    {
        return new ceres::AutoDiffCostFunction<FourDofEdge, 4, 3, 1, 3, 1>(new FourDofEdge(edge));
    }
};

/// A loop found by the adapter, with VINS's record of it.
struct Loop : demo::Loop {
    topoloc_vins::LoopInfo info;

    /// The loop of `loop_info`.
    explicit Loop(const topoloc_vins::LoopInfo &loop_info) : info(loop_info)
    {
        old_index = std::size_t(info.old_index);
        cur_index = std::size_t(info.cur_index);
        relative.t = info.relative_t;
        relative.R = info.relative_q.toRotationMatrix();
    }
};

/// The pose graph's unknowns: position and yaw per keyframe; pitch and roll stay the odometry's.
struct Graph {
    std::vector<std::array<double, 3>> t;
    std::vector<double> yaw, pitch, roll;

    /// The unknowns' initial values: `poses` (the odometry).
    explicit Graph(const std::vector<sim::Pose> &poses)
    {
        for (const sim::Pose &p : poses) {
            const Eigen::Vector3d a = ypr(p.R);
            t.push_back({p.t.x(), p.t.y(), p.t.z()});
            yaw.push_back(a[0]);
            pitch.push_back(a[1]);
            roll.push_back(a[2]);
        }
    }

    /// The edge i -> j that `poses` (the odometry) or a loop measures.
    FourDofEdge edge(std::size_t i, const sim::Pose &relative, double relative_yaw,
                     const Eigen::Vector3d &sigma_t, double sigma_yaw) const
    {
        return {relative.t, relative_yaw, pitch[i], roll[i], sigma_t, sigma_yaw};
    }

    /// Adds `edge` between keyframes i and j to `problem`; returns its block.
    ceres::ResidualBlockId add(ceres::Problem &problem, const FourDofEdge &edge,
                               ceres::LossFunction *loss, std::size_t i, std::size_t j)
    {
        return problem.AddResidualBlock(FourDofEdge::create(edge), loss, t[i].data(), &yaw[i],
                                        t[j].data(), &yaw[j]);
    }

    /// The odometry edge i -> j (see demo::solve_pose_graph).
    void add_odometry(ceres::Problem &problem, std::size_t i, std::size_t j,
                      const sim::Pose &relative, double sigma_t, double sigma_rot)
    {
        const double relative_yaw = yaw[j] - yaw[i]; // the odometry's, as the graph starts there
        add(problem, edge(i, relative, relative_yaw, Eigen::Vector3d::Constant(sigma_t), sigma_rot),
            nullptr, i, j);
    }

    /// The 4-DoF edge of `loop`, with a Huber loss: its relative translation and yaw, sigmas
    /// from the hint covariance (body frames) with the floors of demo.hpp. Returns its block.
    ceres::ResidualBlockId add_loop(ceres::Problem &problem, const Loop &loop)
    {
        const Eigen::Matrix<double, 6, 6> &c = loop.info.covariance;
        Eigen::Vector3d sigma_t;
        for (int k = 0; k < 3; ++k)
            sigma_t[k] = std::max(std::sqrt(std::max(c(3 + k, 3 + k), 0.0)), demo::kLoopSigmaMinM);
        const double sigma_yaw =
            std::max(std::sqrt(std::max(c(2, 2), 0.0)), demo::kLoopSigmaMinRotDeg * M_PI / 180);
        sim::Pose relative;
        relative.t = loop.info.relative_t;
        return add(
            problem,
            edge(loop.old_index, relative, loop.info.relative_yaw * M_PI / 180, sigma_t, sigma_yaw),
            new ceres::HuberLoss(1.0), loop.old_index, loop.cur_index);
    }

    /// The first pose fixed.
    void fix_gauge(ceres::Problem &problem)
    {
        problem.SetParameterBlockConstant(t[0].data());
        problem.SetParameterBlockConstant(&yaw[0]);
    }

    /// Keyframe `i`'s pose as the graph has it.
    sim::Pose pose(std::size_t i) const
    {
        sim::Pose p;
        p.t = Eigen::Vector3d(t[i][0], t[i][1], t[i][2]);
        p.R = rotation(yaw[i], pitch[i], roll[i]);
        return p;
    }
};

/// Builds and solves the 4-DoF graph with demo::solve_pose_graph, dropping loop edges
/// inconsistent with the rest (chi-square of 4 degrees of freedom). Returns the corrected poses.
std::vector<sim::Pose> optimise(const std::vector<sim::Pose> &odometry, std::vector<Loop> &loops)
{
    return demo::solve_pose_graph<Graph>(odometry, loops, demo::kChi2Dof4);
}

/// The experiment: every frame a VINS keyframe through the adapter, then the pose graph and
/// the report.
void run(const demo::Args &args)
{
    const sim::Sequence seq(args.sequence);
    const topoloc::Map describer_map = topoloc::Map::load(args.describer);
    topoloc_vins::Config config;
    config.fx = seq.intrinsics.fx;
    config.fy = seq.intrinsics.fy;
    config.cx = seq.intrinsics.cx;
    config.cy = seq.intrinsics.cy;
    config.qic = sim::body_T_camera().R;
    config.exclude_recent = args.exclude_recent;
    topoloc_vins::LoopDetector detector(describer_map, config);
    std::size_t refused = 0; // errors end the run below: what is left are VINS's refusals
    detector.set_logger([&refused](const std::string &) { ++refused; });

    demo::FrontEnd front_end(args);
    const std::size_t n = demo::keyframe_count(args, seq);
    const std::vector<sim::Pose> odometry(seq.odometry.begin(), seq.odometry.begin() + long(n));
    std::vector<Loop> loops;
    demo::Timings timings;
    for (std::size_t i = 0; i < n; ++i) {
        topoloc_vins::KeyFrame kf;
        kf.index = int(i);
        kf.time_stamp = seq.stamps[i];
        kf.image = seq.grey(i);
        kf.vio_T_w_i = odometry[i].t;
        kf.vio_R_w_i = odometry[i].R;
        // The host's tracked points: ORB corners with their depth, in the VIO world frame.
        const sim::Features f = front_end(seq, i, kf.image);
        const sim::Pose world_T_camera{odometry[i].R * config.qic, odometry[i].t};
        for (std::size_t k = 0; k < f.keypoints.size(); ++k) {
            topoloc_vins::Descriptor d;
            std::copy_n(f.descriptors.ptr<uint8_t>(int(k)), 32, d.begin());
            if (f.camera_points[k].allFinite()) {
                const Eigen::Vector3d w = world_T_camera.R * f.camera_points[k] + world_T_camera.t;
                kf.point_3d.emplace_back(float(w.x()), float(w.y()), float(w.z()));
                kf.point_2d_uv.push_back(f.keypoints[k].pt);
                kf.window_descriptors.push_back(d);
            } else {
                kf.keypoints.push_back(f.keypoints[k].pt);
                kf.descriptors.push_back(d);
            }
        }
        const int old = timings.measure([&] { return detector.detectLoop(kf, kf.index); });
        if (!detector.last_error().empty())
            throw std::runtime_error(detector.last_error());
        for (const topoloc_vins::LoopInfo &earlier : detector.confirmed())
            loops.emplace_back(earlier);
        topoloc_vins::LoopInfo info;
        if (old >= 0 && detector.findConnection(kf.index, old, info))
            loops.emplace_back(info);
    }

    const std::vector<sim::Pose> corrected = optimise(odometry, loops);
    demo::report(args, seq, odometry, corrected, loops, refused, timings,
                 {"VINS's gates", "4-DoF", "detectLoop"});
}

} // namespace

int main(int argc, char **argv) { return demo::run("vins_drift_demo", argc, argv, run); }
