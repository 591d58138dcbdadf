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
#include "topoloc_vins.hpp"

#include "../common/sim_sequence.hpp"

#include <ceres/ceres.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <set>

namespace {

/// Command-line arguments.
struct Args {
  std::string sequence, describer, out;
  bool json = false;
  std::size_t max_keyframes = 0;  // 0 = all
  uint64_t exclude_recent = 30;   // topoloc's default window (chosen on train worlds)
  int orb_features = 500;         // topoloc's own keypoint budget (verify::DEFAULT_KEYPOINTS)
};

[[noreturn]] void usage(const std::string &why) {
  std::cerr << "vins_drift_demo: " << why
            << "\nusage: vins_drift_demo --sequence DIR --describer MAP [--out PNG] [--json]"
               " [--max-keyframes N] [--exclude-recent N] [--orb-features N]\n";
  std::exit(2);
}

Args parse(int argc, char **argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--sequence") a.sequence = value();
    else if (arg == "--describer") a.describer = value();
    else if (arg == "--out") a.out = value();
    else if (arg == "--json") a.json = true;
    else if (arg == "--max-keyframes") a.max_keyframes = std::stoul(value());
    else if (arg == "--exclude-recent") a.exclude_recent = std::stoull(value());
    else if (arg == "--orb-features") a.orb_features = std::stoi(value());
    else usage("unknown argument " + arg);
  }
  if (a.sequence.empty() || a.describer.empty()) usage("--sequence and --describer are required");
  return a;
}

/// Yaw, pitch, roll (radians) of `R = Rz(yaw) Ry(pitch) Rx(roll)`.
Eigen::Vector3d ypr(const Eigen::Matrix3d &R) {
  return {std::atan2(R(1, 0), R(0, 0)), std::asin(-std::clamp(R(2, 0), -1.0, 1.0)),
          std::atan2(R(2, 1), R(2, 2))};
}

template <typename T> Eigen::Matrix<T, 3, 3> rotation(T yaw, double pitch, double roll) {
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

  template <typename T>
  bool operator()(const T *t_i, const T *yaw_i, const T *t_j, const T *yaw_j, T *residual) const {
    const Eigen::Matrix<T, 3, 1> ti(t_i[0], t_i[1], t_i[2]), tj(t_j[0], t_j[1], t_j[2]);
    const Eigen::Matrix<T, 3, 1> local = rotation(yaw_i[0], pitch_i, roll_i).transpose() * (tj - ti);
    for (int k = 0; k < 3; ++k) residual[k] = (local[k] - T(relative_t[k])) / T(sigma_t[k]);
    T angle = yaw_j[0] - yaw_i[0] - T(relative_yaw);
    angle = ceres::atan2(ceres::sin(angle), ceres::cos(angle));
    residual[3] = angle / T(sigma_yaw);
    return true;
  }

  static ceres::CostFunction *create(const FourDofEdge &edge) {
    return new ceres::AutoDiffCostFunction<FourDofEdge, 4, 3, 1, 3, 1>(new FourDofEdge(edge));
  }
};

/// The pose graph's unknowns: position and yaw per keyframe; pitch and roll stay the odometry's.
struct Graph {
  std::vector<std::array<double, 3>> t;
  std::vector<double> yaw, pitch, roll;

  explicit Graph(const std::vector<sim::Pose> &poses) {
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
                   const Eigen::Vector3d &sigma_t, double sigma_yaw) const {
    return {relative.t, relative_yaw, pitch[i], roll[i], sigma_t, sigma_yaw};
  }

  sim::Pose pose(std::size_t i) const {
    sim::Pose p;
    p.t = Eigen::Vector3d(t[i][0], t[i][1], t[i][2]);
    p.R = rotation(yaw[i], pitch[i], roll[i]);
    return p;
  }
};

/// Odometry edge sigmas: 2 cm plus 5 % of the step, and 0.5 degree of yaw per step (the
/// simulator's odometry drifts about 1 % in scale with a yaw bias: the sigmas are looser than
/// its drift so that the loops decide where they disagree).
constexpr double kOdometrySigmaM = 0.02, kOdometrySigmaPerM = 0.05, kOdometrySigmaYawDeg = 0.5;
/// Floors of the loop sigmas taken from the hint covariance.
constexpr double kLoopSigmaMinM = 0.02, kLoopSigmaMinYawDeg = 0.2;
/// Loop edges whose whitened residual exceeds this after a first solve are dropped (chi-square
/// of 4 degrees of freedom at 99.9 %).
constexpr double kLoopChi2 = 18.47;

/// A loop found by the adapter.
struct Loop {
  topoloc_vins::LoopInfo info;
  ceres::ResidualBlockId block = nullptr;
  bool dropped = false;
};

FourDofEdge loop_edge(const Graph &g, const topoloc_vins::LoopInfo &info) {
  const Eigen::Matrix<double, 6, 6> &c = info.covariance;
  Eigen::Vector3d sigma_t;
  for (int k = 0; k < 3; ++k) sigma_t[k] = std::max(std::sqrt(std::max(c(3 + k, 3 + k), 0.0)), kLoopSigmaMinM);
  const double sigma_yaw = std::max(std::sqrt(std::max(c(2, 2), 0.0)), kLoopSigmaMinYawDeg * M_PI / 180);
  sim::Pose relative;
  relative.t = info.relative_t;
  return g.edge(std::size_t(info.old_index), relative, info.relative_yaw * M_PI / 180, sigma_t, sigma_yaw);
}

/// Builds and solves the 4-DoF graph; drops loop edges inconsistent with the rest and solves
/// again. Returns the corrected poses.
std::vector<sim::Pose> optimise(const std::vector<sim::Pose> &odometry, std::vector<Loop> &loops) {
  Graph g(odometry);
  ceres::Problem problem;
  const std::size_t n = odometry.size();
  for (std::size_t j = 1; j < n; ++j) {
    for (std::size_t i = j >= 4 ? j - 4 : 0; i < j; ++i) {  // as loop_fusion: the 4 previous
      const sim::Pose relative = sim::Pose::between(odometry[i], odometry[j]);
      const double sigma = kOdometrySigmaM + kOdometrySigmaPerM * relative.t.norm();
      const double yaw = ypr(odometry[j].R)[0] - ypr(odometry[i].R)[0];
      problem.AddResidualBlock(FourDofEdge::create(g.edge(i, relative, yaw, Eigen::Vector3d::Constant(sigma),
                                                          kOdometrySigmaYawDeg * M_PI / 180 * double(j - i))),
                               nullptr, g.t[i].data(), &g.yaw[i], g.t[j].data(), &g.yaw[j]);
    }
  }
  for (Loop &loop : loops) {
    const std::size_t i = std::size_t(loop.info.old_index), j = std::size_t(loop.info.cur_index);
    loop.block = problem.AddResidualBlock(FourDofEdge::create(loop_edge(g, loop.info)),
                                          new ceres::HuberLoss(1.0), g.t[i].data(), &g.yaw[i],
                                          g.t[j].data(), &g.yaw[j]);
  }
  problem.SetParameterBlockConstant(g.t[0].data());
  problem.SetParameterBlockConstant(&g.yaw[0]);
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.max_num_iterations = 100;
  options.num_threads = 1;
  ceres::Solver::Summary summary;
  for (int round = 0; round < 2; ++round) {
    ceres::Solve(options, &problem, &summary);
    bool changed = false;
    for (Loop &loop : loops) {
      if (loop.dropped) continue;
      double cost = 0;
      problem.EvaluateResidualBlock(loop.block, false, &cost, nullptr, nullptr);
      // `cost` is half the squared whitened residual before the loss (apply_loss false).
      if (2 * cost > kLoopChi2) {
        problem.RemoveResidualBlock(loop.block);
        loop.dropped = changed = true;
      }
    }
    if (!changed) break;
  }
  std::vector<sim::Pose> corrected;
  for (std::size_t i = 0; i < n; ++i) corrected.push_back(g.pose(i));
  return corrected;
}

/// True when the loop's relative pose is off the ground truth's by more than 5 degrees or
/// 0.5 m (the bound `topoloc loops --truth` uses for a usable constraint).
bool is_false(const sim::Sequence &seq, const topoloc_vins::LoopInfo &info) {
  const sim::Pose truth = sim::Pose::between(seq.truth[std::size_t(info.old_index)],
                                             seq.truth[std::size_t(info.cur_index)]);
  const Eigen::AngleAxisd error(truth.R.transpose() * info.relative_q.toRotationMatrix());
  return error.angle() * 180 / M_PI > 5.0 || (truth.t - info.relative_t).norm() > 0.5;
}

}  // namespace

int main(int argc, char **argv) {
  const Args args = parse(argc, argv);
  try {
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
    std::size_t errors = 0;
    detector.set_logger([&errors](const std::string &) { ++errors; });

    cv::Ptr<cv::ORB> orb = cv::ORB::create(args.orb_features);
    const std::size_t n = args.max_keyframes ? std::min(args.max_keyframes, seq.size()) : seq.size();
    const std::vector<sim::Pose> odometry(seq.odometry.begin(), seq.odometry.begin() + long(n));
    std::vector<Loop> loops;
    std::vector<double> ms;
    for (std::size_t i = 0; i < n; ++i) {
      topoloc_vins::KeyFrame kf;
      kf.index = int(i);
      kf.time_stamp = seq.stamps[i];
      kf.image = seq.grey(i);
      kf.vio_T_w_i = odometry[i].t;
      kf.vio_R_w_i = odometry[i].R;
      // The host's tracked points: ORB corners with their depth, in the VIO world frame.
      const sim::Features f = sim::extract(*orb, kf.image, seq.depth(i), seq.intrinsics);
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
      const auto start = std::chrono::steady_clock::now();
      const int old = detector.detectLoop(kf, kf.index);
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
      if (!detector.last_error().empty()) throw std::runtime_error(detector.last_error());
      for (const topoloc_vins::LoopInfo &earlier : detector.confirmed()) loops.push_back({earlier});
      topoloc_vins::LoopInfo info;
      if (old >= 0 && detector.findConnection(kf.index, old, info)) loops.push_back({info});
    }

    const std::vector<sim::Pose> corrected = optimise(odometry, loops);
    const topoloc::TrajectoryReport raw = sim::ate_sim3(seq, odometry);
    const topoloc::TrajectoryReport fixed = sim::ate_sim3(seq, corrected);
    std::size_t used = 0, false_used = 0, dropped = 0, false_dropped = 0;
    std::vector<sim::Edge> edges;
    for (const Loop &loop : loops) {
      const bool wrong = is_false(seq, loop.info);
      if (loop.dropped) {
        ++dropped;
        false_dropped += wrong;
      } else {
        ++used;
        false_used += wrong;
        edges.emplace_back(std::size_t(loop.info.old_index), std::size_t(loop.info.cur_index));
      }
    }
    if (!args.out.empty()) sim::plot(args.out, seq, odometry, raw, corrected, fixed, edges);
    std::sort(ms.begin(), ms.end());
    const double median_ms = ms.empty() ? 0.0 : ms[ms.size() / 2];
    const double ratio = fixed.ate_m.rmse / raw.ate_m.rmse;
    if (args.json) {
      std::printf("{\"keyframes\": %zu, \"loops\": %zu, \"loops_used\": %zu, \"false_used\": %zu, "
                  "\"dropped\": %zu, \"false_dropped\": %zu, \"refused_by_gates\": %zu, "
                  "\"ate_raw_m\": %.4f, \"ate_corrected_m\": %.4f, \"ate_ratio\": %.4f, "
                  "\"keyframe_ms_median\": %.1f}\n",
                  n, loops.size(), used, false_used, dropped, false_dropped, errors, raw.ate_m.rmse,
                  fixed.ate_m.rmse, ratio, median_ms);
    } else {
      std::printf("%s: %zu keyframes, %zu loops from topoloc (%zu refused by VINS's gates)\n",
                  args.sequence.c_str(), n, loops.size(), errors);
      std::printf("pose graph (4-DoF, Ceres): %zu loops used (%zu false), %zu dropped as "
                  "inconsistent (%zu false)\n", used, false_used, dropped, false_dropped);
      std::printf("ATE RMSE (Sim3): raw odometry %.3f m, corrected %.3f m (%.1f %%)\n",
                  raw.ate_m.rmse, fixed.ate_m.rmse, 100 * ratio);
      std::printf("detectLoop: median %.1f ms per keyframe\n", median_ms);
      if (!args.out.empty()) std::printf("wrote %s\n", args.out.c_str());
    }
    return 0;
  } catch (const std::exception &e) {
    std::cerr << "vins_drift_demo: " << e.what() << "\n";
    return 1;
  }
}
