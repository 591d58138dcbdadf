// What the drift-correction demos (vins/vins_drift_demo.cpp, orbslam/orbslam_drift_demo.cpp)
// share around their adapters and pose graphs: the command line, the host's front end (ORB
// keypoints after CLAHE), the odometry edges and their sigmas, the loop sigma floors, the Ceres
// solve that drops inconsistent loop edges, the judgement of loops against ground truth, the
// timing of the adapter calls and the report (text or JSON, and the PNG).
//
// Not part of the adapters: a host has its own front end, pose graph and reporting.
#ifndef TOPOLOC_EXAMPLES_DEMO_HPP
#define TOPOLOC_EXAMPLES_DEMO_HPP

#include "sim_sequence.hpp"

#include <ceres/ceres.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace demo {

// ---------------------------------------------------------------------------------------------
// Command line
// ---------------------------------------------------------------------------------------------

/// Command-line arguments of a drift demo, with their defaults.
struct Args {
    std::string sequence;  ///< `--sequence`: a `traj-00i` folder of `topoloc simulate --depth`.
    std::string describer; ///< `--describer`: a map whose describer describes the images.
    std::string out;       ///< `--out`: the PNG to write ("" = none).
    bool json = false;     ///< `--json`: one JSON line instead of the text report.
    std::size_t max_keyframes = 0; ///< `--max-keyframes`: the first N frames only (0 = all).
    /// `--exclude-recent`: topoloc's default window (`topoloc_loop_options::exclude_recent_ids`).
    uint64_t exclude_recent = topoloc::default_loop_options().exclude_recent_ids;
    int orb_features =
        500; ///< `--orb-features`: topoloc's own keypoint budget (verify::DEFAULT_KEYPOINTS).
    int fast_threshold = 20; ///< `--fast-threshold`: OpenCV's ORB default.
    double clahe =
        2.0; ///< `--clahe`: CLAHE clip limit before ORB, 0 = off (chosen on train 1-2 night).
};

/// The usage line of `program`.
inline std::string usage_line(const char *program)
{
    return std::string("usage: ") + program +
           " --sequence DIR --describer MAP [--out PNG] [--json] [--max-keyframes N]"
           " [--exclude-recent N] [--orb-features N] [--fast-threshold N] [--clahe CLIP]";
}

/// Prints `why` and the usage line to stderr and exits 2 (bad arguments).
[[noreturn]] inline void usage(const char *program, const std::string &why)
{
    std::cerr << program << ": " << why << "\n" << usage_line(program) << "\n";
    std::exit(2);
}

/// `text` as a whole non-negative integer of at most `max`; exits 2 naming `flag` otherwise.
inline unsigned long long parse_count(const char *program, const std::string &flag,
                                      const std::string &text, unsigned long long max)
{
    errno = 0;
    char *end = nullptr;
    const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
    const bool digits = !text.empty() && text.find_first_not_of("0123456789") == std::string::npos;
    if (!digits || errno != 0 || *end != '\0' || v > max) {
        usage(program, flag + " needs a whole number from 0 to " + std::to_string(max) + ", got '" +
                           text + "'");
    }
    return v;
}

/// `text` as a finite number >= 0; exits 2 naming `flag` otherwise.
inline double parse_real(const char *program, const std::string &flag, const std::string &text)
{
    errno = 0;
    char *end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || errno != 0 || *end != '\0' || !std::isfinite(v) || v < 0) {
        usage(program, flag + " needs a number >= 0, got '" + text + "'");
    }
    return v;
}

/// Parses the command line; bad or missing arguments exit 2 with the usage line, `--help`
/// prints it and exits 0.
inline Args parse_args(const char *program, int argc, char **argv)
{
    Args a;
    const unsigned long long int_max = std::numeric_limits<int>::max();
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc)
                usage(program, arg + " needs a value");
            return argv[++i];
        };
        if (arg == "--help" || arg == "-h") {
            std::cout << usage_line(program) << "\n";
            std::exit(0);
        } else if (arg == "--sequence")
            a.sequence = value();
        else if (arg == "--describer")
            a.describer = value();
        else if (arg == "--out")
            a.out = value();
        else if (arg == "--json")
            a.json = true;
        else if (arg == "--max-keyframes")
            a.max_keyframes = std::size_t(
                parse_count(program, arg, value(), std::numeric_limits<std::size_t>::max()));
        else if (arg == "--exclude-recent")
            a.exclude_recent =
                parse_count(program, arg, value(), std::numeric_limits<uint64_t>::max());
        else if (arg == "--orb-features")
            a.orb_features = int(parse_count(program, arg, value(), int_max));
        else if (arg == "--fast-threshold")
            a.fast_threshold = int(parse_count(program, arg, value(), 255));
        else if (arg == "--clahe")
            a.clahe = parse_real(program, arg, value());
        else
            usage(program, "unknown argument " + arg);
    }
    if (a.sequence.empty() || a.describer.empty())
        usage(program, "--sequence and --describer are required");
    if (a.orb_features < 1)
        usage(program, "--orb-features must be at least 1");
    return a;
}

/// Runs a demo: parses the arguments (exit 2 on bad ones), then `body(args)`; an exception
/// (a missing file, bad data, a topoloc or OpenCV error) is printed and exits 1.
template <typename Body> int run(const char *program, int argc, char **argv, Body &&body)
{
    const Args args = parse_args(program, argc, argv);
    try {
        body(args);
        return 0;
    } catch (const std::exception &e) {
        std::cerr << program << ": " << e.what() << "\n";
        return 1;
    }
}

/// How many frames of `seq` the run uses as keyframes (`--max-keyframes`, every frame a
/// keyframe). Throws for a sequence without frames.
inline std::size_t keyframe_count(const Args &args, const sim::Sequence &seq)
{
    if (seq.size() == 0)
        throw std::runtime_error(seq.dir + ": the sequence has no frames");
    return args.max_keyframes ? std::min(args.max_keyframes, seq.size()) : seq.size();
}

// ---------------------------------------------------------------------------------------------
// Front end
// ---------------------------------------------------------------------------------------------

/// The host's front end: ORB (`--orb-features`, `--fast-threshold`) on the image equalised by
/// CLAHE (`--clahe`, 8x8 tiles; 0 = raw image), with the depth image's 3D points.
class FrontEnd {
public:
    /// The ORB detector and CLAHE of `args`.
    explicit FrontEnd(const Args &args)
        : orb_(cv::ORB::create(args.orb_features)),
          clahe_(cv::createCLAHE(args.clahe > 0 ? args.clahe : 1.0, cv::Size(8, 8))),
          use_clahe_(args.clahe > 0)
    {
        orb_->setFastThreshold(args.fast_threshold);
    }

    /// The features of frame `i` of `seq`, whose grey image is `grey` (the host gives the raw
    /// image to the adapter; only the features see the equalised one).
    sim::Features operator()(const sim::Sequence &seq, std::size_t i, const cv::Mat &grey)
    {
        return sim::extract(*orb_, grey, seq.depth(i), seq.intrinsics,
                            use_clahe_ ? clahe_.get() : nullptr);
    }

private:
    cv::Ptr<cv::ORB> orb_;
    cv::Ptr<cv::CLAHE> clahe_;
    bool use_clahe_;
};

/// Milliseconds of the adapter calls, one entry per keyframe.
struct Timings {
    std::vector<double> ms;

    /// Runs `call()`, appends its duration and returns its result.
    template <typename Call> decltype(auto) measure(Call &&call)
    {
        const auto start = std::chrono::steady_clock::now();
        struct Record { // appends the duration on the way out, also for a void `call`
            Timings &timings;
            std::chrono::steady_clock::time_point start;
            ~Record()
            {
                timings.ms.push_back(std::chrono::duration<double, std::milli>(
                                         std::chrono::steady_clock::now() - start)
                                         .count());
            }
        } record{*this, start};
        return call();
    }

    /// The median (the upper one for an even count), 0 when nothing was measured.
    double median() const
    {
        std::vector<double> sorted = ms;
        std::sort(sorted.begin(), sorted.end());
        return sorted.empty() ? 0.0 : sorted[sorted.size() / 2];
    }
};

// ---------------------------------------------------------------------------------------------
// Pose graph
// ---------------------------------------------------------------------------------------------

/// Odometry edge sigmas: 2 cm plus 5 % of the step, and 0.5 degree of rotation per step (the
/// simulator's odometry drifts about 1 % in scale with a yaw bias: the sigmas are looser than
/// its drift so that the loops decide where they disagree).
constexpr double kOdometrySigmaM = 0.02, kOdometrySigmaPerM = 0.05, kOdometrySigmaRotDeg = 0.5;
/// Each keyframe gets odometry edges from this many previous ones (as loop_fusion).
constexpr std::size_t kOdometryNeighbours = 4;
/// Floors of the loop sigmas taken from the hint covariance.
constexpr double kLoopSigmaMinM = 0.02, kLoopSigmaMinRotDeg = 0.2;
/// Chi-square at 99.9 % of 4 degrees of freedom (VINS's x, y, z, yaw edges) and of 6 (SE3
/// edges): loop edges whose whitened squared residual exceeds it after a solve are dropped.
constexpr double kChi2Dof4 = 18.47, kChi2Dof6 = 22.46;

/// Calls `edge(i, j, relative, sigma_t, sigma_rot)` for every odometry edge i -> j (the
/// `kOdometryNeighbours` keyframes before j): `relative` is `odometry[i]^-1 odometry[j]`,
/// `sigma_t` its translation sigma (m, each axis), `sigma_rot` its rotation sigma (rad, each
/// rotation axis the graph has).
template <typename Edge>
void for_each_odometry_edge(const std::vector<sim::Pose> &odometry, Edge &&edge)
{
    for (std::size_t j = 1; j < odometry.size(); ++j) {
        for (std::size_t i = j >= kOdometryNeighbours ? j - kOdometryNeighbours : 0; i < j; ++i) {
            const sim::Pose relative = sim::Pose::between(odometry[i], odometry[j]);
            const double sigma_t = kOdometrySigmaM + kOdometrySigmaPerM * relative.t.norm();
            const double sigma_rot = kOdometrySigmaRotDeg * M_PI / 180 * double(j - i);
            edge(i, j, relative, sigma_t, sigma_rot);
        }
    }
}

/// A loop closure as the pose graph and the judge see it: keyframe `cur` in keyframe `old`'s
/// body frame, and its residual block. Demos derive from it to keep their adapter's record.
struct Loop {
    std::size_t old_index = 0;              ///< The earlier keyframe.
    std::size_t cur_index = 0;              ///< The keyframe that closed the loop.
    sim::Pose relative;                     ///< `body_old_T_body_cur` as the adapter measured it.
    ceres::ResidualBlockId block = nullptr; ///< Its edge in the Ceres problem.
    bool dropped = false;                   ///< Removed as inconsistent with the rest of the graph.
};

/// The Ceres options of both pose graphs: sparse normal Cholesky, 100 iterations, one thread.
inline ceres::Solver::Options solver_options()
{
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    options.max_num_iterations = 100;
    options.num_threads = 1;
    return options;
}

/// Solves `problem`, then removes the loop edges whose whitened squared residual (before the
/// robust loss) exceeds `chi2` and solves again, until no edge is dropped (it ends: each solve
/// but the last drops at least one edge), so that no edge reported as dropped is in the
/// solution. `L` derives from `Loop`; each loop's `block` must be in `problem`.
template <typename L>
void solve_dropping(ceres::Problem &problem, std::vector<L> &loops, double chi2)
{
    const ceres::Solver::Options options = solver_options();
    ceres::Solver::Summary summary;
    for (;;) {
        ceres::Solve(options, &problem, &summary);
        bool changed = false;
        for (Loop &loop : loops) {
            if (loop.dropped)
                continue;
            double cost = 0;
            problem.EvaluateResidualBlock(loop.block, false, &cost, nullptr, nullptr);
            // `cost` is half the squared whitened residual before the loss (apply_loss false).
            if (2 * cost > chi2) {
                problem.RemoveResidualBlock(loop.block);
                loop.dropped = changed = true;
            }
        }
        if (!changed)
            break;
    }
}

/// Builds and solves a demo's pose graph over `odometry` and `loops`; returns the corrected
/// poses. `Graph(odometry)` holds the unknowns, started at the odometry;
/// `g.add_odometry(problem, i, j, relative, sigma_t, sigma_rot)` adds each edge of
/// `for_each_odometry_edge`, `g.add_loop(problem, loop)` each loop's edge (with a robust loss)
/// and returns its block, and `g.fix_gauge(problem)` holds the first pose (and sets any
/// manifold). `solve_dropping` with `chi2` then drops the loop edges inconsistent with the rest,
/// and `g.pose(i)` reads each keyframe's pose back.
template <typename Graph, typename L>
std::vector<sim::Pose> solve_pose_graph(const std::vector<sim::Pose> &odometry,
                                        std::vector<L> &loops, double chi2)
{
    Graph g(odometry);
    ceres::Problem problem;
    for_each_odometry_edge(odometry, [&](std::size_t i, std::size_t j, const sim::Pose &relative,
                                         double sigma_t, double sigma_rot) {
        g.add_odometry(problem, i, j, relative, sigma_t, sigma_rot);
    });
    for (L &loop : loops)
        loop.block = g.add_loop(problem, loop);
    g.fix_gauge(problem);
    solve_dropping(problem, loops, chi2);
    std::vector<sim::Pose> corrected;
    for (std::size_t i = 0; i < odometry.size(); ++i)
        corrected.push_back(g.pose(i));
    return corrected;
}

/// The adjoint of `T` on se(3) tangents ordered rotation then translation: `[R 0; [t]x R R]`.
/// A right perturbation `xi` of a pose in frame a is one of `Ad(b_T_a) xi` in frame b.
inline Eigen::Matrix<double, 6, 6> adjoint(const sim::Pose &T)
{
    Eigen::Matrix3d tx;
    tx << 0, -T.t.z(), T.t.y(), T.t.z(), 0, -T.t.x(), -T.t.y(), T.t.x(), 0;
    Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Zero();
    a.topLeftCorner<3, 3>() = T.R;
    a.bottomLeftCorner<3, 3>() = tx * T.R;
    a.bottomRightCorner<3, 3>() = T.R;
    return a;
}

// ---------------------------------------------------------------------------------------------
// Judgement and report
// ---------------------------------------------------------------------------------------------

/// True when the loop's relative pose is off the ground truth's by more than 5 degrees or
/// 0.5 m (the bound `topoloc loops --truth` uses for a usable constraint).
inline bool is_false(const sim::Sequence &seq, const Loop &loop)
{
    const sim::Pose truth =
        sim::Pose::between(seq.truth[loop.old_index], seq.truth[loop.cur_index]);
    const Eigen::AngleAxisd error(truth.R.transpose() * loop.relative.R);
    return error.angle() * 180 / M_PI > 5.0 || (truth.t - loop.relative.t).norm() > 0.5;
}

/// The words of a demo's text report.
struct Labels {
    const char *gates; ///< Who refused loops: "VINS's gates".
    const char *graph; ///< The pose graph: "4-DoF".
    const char *call;  ///< The timed adapter call(s): "detectLoop".
};

/// The figures a demo reports (text or the JSON keys of the same names).
struct Summary {
    std::size_t keyframes = 0, loops = 0, loops_used = 0, false_used = 0, dropped = 0,
                false_dropped = 0, refused_by_gates = 0;
    double ate_raw_m = 0, ate_corrected_m = 0, ate_ratio = 0, keyframe_ms_median = 0;
    bool sim3 = true; ///< The ATE is Sim3-aligned (else unaligned: see `ate_reports`).
};

/// Prints `s` to stdout: one JSON line with `--json`, else the text report with `labels`.
inline void print(const Args &args, const Summary &s, const Labels &labels)
{
    if (args.json) {
        std::printf(
            "{\"keyframes\": %zu, \"loops\": %zu, \"loops_used\": %zu, \"false_used\": %zu, "
            "\"dropped\": %zu, \"false_dropped\": %zu, \"refused_by_gates\": %zu, "
            "\"ate_raw_m\": %.4f, \"ate_corrected_m\": %.4f, \"ate_ratio\": %.4f, "
            "\"ate_alignment\": \"%s\", \"keyframe_ms_median\": %.1f}\n",
            s.keyframes, s.loops, s.loops_used, s.false_used, s.dropped, s.false_dropped,
            s.refused_by_gates, s.ate_raw_m, s.ate_corrected_m, s.ate_ratio,
            s.sim3 ? "sim3" : "none", s.keyframe_ms_median);
        return;
    }
    std::printf("%s: %zu keyframes, %zu loops from topoloc (%zu refused by %s)\n",
                args.sequence.c_str(), s.keyframes, s.loops, s.refused_by_gates, labels.gates);
    std::printf("pose graph (%s, Ceres): %zu loops used (%zu false), %zu dropped as "
                "inconsistent (%zu false)\n",
                labels.graph, s.loops_used, s.false_used, s.dropped, s.false_dropped);
    std::printf("ATE RMSE (%s): raw odometry %.3f m, corrected %.3f m (%.1f %%)\n",
                s.sim3 ? "Sim3" : "unaligned", s.ate_raw_m, s.ate_corrected_m, 100 * s.ate_ratio);
    std::printf("%s: median %.1f ms per keyframe\n", labels.call, s.keyframe_ms_median);
    if (!args.out.empty())
        std::printf("wrote %s\n", args.out.c_str());
}

/// The ATE of a run's raw and corrected trajectories.
struct AteReports {
    topoloc::TrajectoryReport raw, corrected;
    bool sim3 = true; ///< Both Sim3-aligned (else both unaligned).
};

/// The ATE of the raw and the corrected trajectory after a Sim3 alignment; when the positions
/// are too degenerate to align (collinear: a straight run, e.g. a short `--max-keyframes`),
/// both unaligned, with a note on stderr (both start at the truth's first pose: the
/// simulator's odometry does, and the graph keeps the first pose).
inline AteReports ate_reports(const sim::Sequence &seq, const std::vector<sim::Pose> &odometry,
                              const std::vector<sim::Pose> &corrected)
{
    try {
        return {sim::ate_sim3(seq, odometry), sim::ate_sim3(seq, corrected), true};
    } catch (const topoloc::Error &e) {
        if (e.status() != TOPOLOC_ERR_INVALID_ARGUMENT)
            throw;
        std::cerr << "note: no Sim3 alignment (" << e.message() << "); ATE without alignment\n";
        return {sim::ate(seq, odometry, TOPOLOC_ALIGN_NONE),
                sim::ate(seq, corrected, TOPOLOC_ALIGN_NONE), false};
    }
}

/// Judges the loops, measures both trajectories' ATE (`ate_reports`), writes the PNG (`--out`) and
/// prints the report. `odometry` and `corrected` hold the keyframes' poses; `L` derives from
/// `Loop`. Throws when the ATE cannot be computed or the PNG cannot be written.
template <typename L>
void report(const Args &args, const sim::Sequence &seq, const std::vector<sim::Pose> &odometry,
            const std::vector<sim::Pose> &corrected, const std::vector<L> &loops,
            std::size_t refused_by_gates, const Timings &timings, const Labels &labels)
{
    const AteReports ate = ate_reports(seq, odometry, corrected);
    const topoloc::TrajectoryReport &raw = ate.raw, &fixed = ate.corrected;
    Summary s;
    s.keyframes = odometry.size();
    s.loops = loops.size();
    s.refused_by_gates = refused_by_gates;
    std::vector<sim::Edge> edges;
    for (const Loop &loop : loops) {
        const bool wrong = is_false(seq, loop);
        if (loop.dropped) {
            ++s.dropped;
            s.false_dropped += wrong;
        } else {
            ++s.loops_used;
            s.false_used += wrong;
            edges.emplace_back(loop.old_index, loop.cur_index);
        }
    }
    if (!args.out.empty())
        sim::plot(args.out, seq, odometry, raw, corrected, fixed, edges);
    s.sim3 = ate.sim3;
    s.ate_raw_m = raw.ate_m.rmse;
    s.ate_corrected_m = fixed.ate_m.rmse;
    s.ate_ratio = fixed.ate_m.rmse / raw.ate_m.rmse;
    s.keyframe_ms_median = timings.median();
    print(args, s, labels);
}

} // namespace demo

#endif // TOPOLOC_EXAMPLES_DEMO_HPP
