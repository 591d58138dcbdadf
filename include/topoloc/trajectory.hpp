/*
 * topoloc/trajectory.hpp: trajectory metrics (ABI 1.11; part of topoloc.hpp, which has the
 * overview): ATE, ARE, RPE and R_traj of an estimated trajectory against ground truth.
 */

#ifndef TOPOLOC_TRAJECTORY_HPP
#define TOPOLOC_TRAJECTORY_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"

#include <array>
#include <string>
#include <vector>

namespace topoloc {

/// What `evaluate_trajectory` measured (the C struct: `pairs`, `scale`, `alignment`, `ate_m`,
/// `are_deg`, `rpe_m`, `rpe_deg` with rmse/mean/median/std/min/max, path lengths and
/// `length_ratio`, R_traj).
using TrajectoryReport = topoloc_trajectory_report;

/// One pose of a trajectory in TUM's layout: seconds, then `world_T_body` as
/// `tx ty tz qx qy qz qw` (unit quaternion, w last).
struct TimedPose {
    double timestamp = 0.0;
    std::array<double, 7> pose{0, 0, 0, 0, 0, 0, 1};
};

/// Judges `estimate` against `reference` as `evo_ape` / `evo_rpe` do
/// (`topoloc_trajectory_evaluate`). Thread-safe. Throws `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT`
/// for decreasing timestamps, a quaternion not of norm 1, no associated pair, too few pairs or
/// degenerate positions; `_NON_FINITE`; `_INVALID_OPTION`).
[[nodiscard]] inline TrajectoryReport
evaluate_trajectory(const std::vector<TimedPose> &reference, const std::vector<TimedPose> &estimate,
                    const TrajectoryOptions &options = default_trajectory_options())
{
    auto split = [](const std::vector<TimedPose> &t, std::vector<double> &stamps,
                    std::vector<double> &poses) {
        for (const TimedPose &p : t) {
            stamps.push_back(p.timestamp);
            poses.insert(poses.end(), p.pose.begin(), p.pose.end());
        }
    };
    std::vector<double> ref_t, ref_p, est_t, est_p;
    split(reference, ref_t, ref_p);
    split(estimate, est_t, est_p);
    TrajectoryReport report = detail::filled(&topoloc_trajectory_report_init);
    check(topoloc_trajectory_evaluate(ref_t.data(), ref_p.data(), reference.size(), est_t.data(),
                                      est_p.data(), estimate.size(), &options, &report));
    return report;
}

/// `evaluate_trajectory` of two files (`topoloc_trajectory_evaluate_files`) in `format`
/// (`TOPOLOC_TRAJECTORY_DETECT` tells each file's format: TUM, KITTI or EuRoC). Throws `Error`
/// (`TOPOLOC_ERR_IO`, `_INVALID_ARGUMENT` for a malformed line, and those of
/// `evaluate_trajectory`).
[[nodiscard]] inline TrajectoryReport
evaluate_trajectory_files(const std::string &reference_path, const std::string &estimate_path,
                          topoloc_trajectory_format format = TOPOLOC_TRAJECTORY_DETECT,
                          const TrajectoryOptions &options = default_trajectory_options())
{
    TrajectoryReport report = detail::filled(&topoloc_trajectory_report_init);
    check(topoloc_trajectory_evaluate_files(reference_path.c_str(), estimate_path.c_str(), format,
                                            &options, &report));
    return report;
}

} // namespace topoloc

#endif // TOPOLOC_TRAJECTORY_HPP
