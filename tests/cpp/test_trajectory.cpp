// Tests of the trajectory metrics of the C++ layer (include/topoloc.hpp, ABI 1.11):
// `evaluate_trajectory` recovers a scaled, moved copy of a loop with Sim3 alignment, a rigid
// alignment cannot; `evaluate_trajectory_files` reads TUM files; bad input throws `Error` with
// the C status. Built and run by tests/cpp/run.sh, normally and under ASan+UBSan.

#include "topoloc.hpp"

#include "harness.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>

namespace {

// A loop of `n` poses at 10 Hz, scaled by `scale` and moved by `dx` along x.
std::vector<topoloc::TimedPose> loop(std::size_t n, double scale, double dx)
{
    std::vector<topoloc::TimedPose> poses;
    for (std::size_t i = 0; i < n; ++i) {
        const double a = 6.283185307179586 * double(i) / double(n);
        topoloc::TimedPose p;
        p.timestamp = 0.1 * double(i);
        p.pose = {scale * 3.0 * std::cos(a) + dx,
                  scale * 2.0 * std::sin(a),
                  scale * 0.2 * double(i) / double(n),
                  0.0,
                  0.0,
                  std::sin(a / 2),
                  std::cos(a / 2)};
        poses.push_back(p);
    }
    return poses;
}

} // namespace

TEST(sim3_alignment_recovers_a_scaled_copy)
{
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 11, "trajectory metrics are ABI 1.11");
    const auto truth = loop(50, 1.0, 0.0);
    const auto estimate = loop(50, 0.25, -2.0);
    const topoloc::TrajectoryReport report = topoloc::evaluate_trajectory(truth, estimate);
    CHECK_EQ(report.pairs, std::size_t{50});
    CHECK(report.ate_m.rmse < 1e-9 && std::fabs(report.scale - 4.0) < 1e-9);
    CHECK(std::fabs(report.length_ratio - 1.0) < 1e-9);
    topoloc::TrajectoryOptions rigid = topoloc::default_trajectory_options();
    CHECK(rigid.alignment == TOPOLOC_ALIGN_SIM3);
    rigid.alignment = TOPOLOC_ALIGN_SE3;
    CHECK(topoloc::evaluate_trajectory(truth, estimate, rigid).ate_m.rmse > 0.5);
}

TEST(files_and_bad_input)
{
    const auto truth = loop(30, 1.0, 0.0);
    const std::string path = "/tmp/topoloc-cpp-trajectory.tum";
    {
        std::ofstream out(path);
        out.precision(17);
        for (const auto &p : truth) {
            out << p.timestamp;
            for (double v : p.pose)
                out << ' ' << v;
            out << '\n';
        }
    }
    const auto report = topoloc::evaluate_trajectory_files(path, path);
    CHECK(report.pairs == 30 && report.ate_m.rmse < 1e-9);
    CHECK_THROWS_STATUS(topoloc::evaluate_trajectory_files(path, path + ".missing"),
                        TOPOLOC_ERR_IO);
    auto bad = truth;
    bad[4].pose[6] = 2.0; // not a unit quaternion
    CHECK_THROWS_STATUS(topoloc::evaluate_trajectory(truth, bad), TOPOLOC_ERR_INVALID_ARGUMENT);
    bad = truth;
    bad[2].pose[0] = std::nan("");
    CHECK_THROWS_STATUS(topoloc::evaluate_trajectory(truth, bad), TOPOLOC_ERR_NON_FINITE);
    topoloc::TrajectoryOptions options = topoloc::default_trajectory_options();
    options.rpe_delta = 0;
    CHECK_THROWS_STATUS(topoloc::evaluate_trajectory(truth, truth, options),
                        TOPOLOC_ERR_INVALID_OPTION);
    CHECK(std::remove(path.c_str()) == 0);
}

int main() { return run_all_tests(); }
