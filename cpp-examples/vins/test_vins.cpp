// Tests of the VINS adapter (topoloc_vins.hpp): a revisit gives detectLoop's old index and the
// loop_info VINS's findConnection would give (relative t, q, yaw in the body frames), VINS's
// gates refuse what they would refuse, and bad keyframes (out of order, duplicate, NaN pose,
// another image size, arrays of different lengths, use after clear) give a logged error, no
// loop and an unchanged detector, also when the logger throws. Against loop_fusion's contracts:
// confirmed loops keep earliest_loop_index and the optimisation queue consistent (a stand-in of
// optimize4DoF's walk and assert), a second sequence (new VIO frame, restarted clock) finds the
// first, points come as normalized coordinates in their origin pose, extrinsics follow the
// online estimate (none before it), and a loop needs 3D points on the current keyframe only. Images: the textured places of tests/cpp/harness.hpp (their
// VLAD map is the describer); points: the two views of the same scene from harness.hpp.
#include "topoloc_vins.hpp"

#include "../../tests/cpp/harness.hpp"

namespace {

/// The optical camera in a body with x forward, z up.
Eigen::Matrix3d camera_in_body()
{
    Eigen::Matrix3d R;
    R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    return R;
}

/// The second camera of `two_views()` in the first's frame: 0.3 m right, 0.1 m ahead, turned
/// 3 degrees about the camera's y axis.
Eigen::Isometry3d second_in_first()
{
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() =
        Eigen::AngleAxisd(3.0 * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
    pose.translation() = Eigen::Vector3d(0.3, 0.0, 0.1);
    return pose;
}

/// The body pose of the revisit when the first keyframe's body is the world origin.
Eigen::Isometry3d revisit_body()
{
    Eigen::Isometry3d body_T_camera = Eigen::Isometry3d::Identity();
    body_T_camera.linear() = camera_in_body();
    return body_T_camera * second_in_first() * body_T_camera.inverse();
}

topoloc_vins::Config test_config()
{
    topoloc_vins::Config config;
    config.fx = config.fy = 300;
    config.cx = 160;
    config.cy = 120;
    config.qic = camera_in_body();
    config.exclude_recent = 5;
    config.options.exclude_recent_s = 0;
    config.options.consistent_keyframes = 1;
    return config;
}

cv::Mat place_image(uint32_t place)
{
    const std::vector<uint8_t> &px = places_pixels()[place];
    return cv::Mat(int(kImgH), int(kImgW), CV_8UC1, const_cast<uint8_t *>(px.data()));
}

/// Keyframe `index` showing place `place` from body pose `body`; with the scene's points seen
/// from the first (`revisit` false) or the second camera, or without points (`points` false:
/// the adapter extracts ORB itself).
topoloc_vins::KeyFrame keyframe(int index, uint32_t place, const Eigen::Isometry3d &body,
                                bool points, bool revisit)
{
    topoloc_vins::KeyFrame kf;
    kf.index = index;
    kf.time_stamp = index;
    kf.image = place_image(place);
    kf.vio_T_w_i = body.translation();
    kf.vio_R_w_i = body.linear();
    if (!points)
        return kf;
    const TwoViews &v = two_views();
    const Eigen::Matrix3d R = camera_in_body(); // the first camera's body is the world
    for (std::size_t i = 0; i < kLoopPoints; ++i) {
        const Eigen::Vector3d world =
            R * Eigen::Vector3d(v.scene[3 * i], v.scene[3 * i + 1], v.scene[3 * i + 2]);
        const std::vector<float> &uv = revisit ? v.second : v.first;
        kf.point_3d.emplace_back(float(world.x()), float(world.y()), float(world.z()));
        kf.point_2d_uv.emplace_back(uv[2 * i], uv[2 * i + 1]);
        topoloc_vins::Descriptor d;
        std::copy_n(v.descriptors.begin() + long(32 * i), 32, d.begin());
        kf.window_descriptors.push_back(d);
    }
    return kf;
}

/// The first keyframe, fillers 1..6 at other places (ORB extracted by the adapter), and the
/// revisit 7 of the first place: returns detectLoop's answer for the revisit.
int run_revisit(topoloc_vins::LoopDetector &detector)
{
    CHECK_EQ(detector.detectLoop(keyframe(0, 0, Eigen::Isometry3d::Identity(), true, false), 0),
             -1);
    for (int i = 1; i <= 6; ++i) {
        Eigen::Isometry3d body = Eigen::Isometry3d::Identity();
        body.translation() = Eigen::Vector3d(5.0 * i, 0, 0);
        CHECK_EQ(detector.detectLoop(keyframe(i, uint32_t(i), body, false, false), i), -1);
        CHECK(detector.last_error().empty());
    }
    return detector.detectLoop(keyframe(7, 0, revisit_body(), true, true), 7);
}

TEST(a_revisit_gives_vins_loop_info)
{
    topoloc_vins::LoopDetector detector(image_map(), test_config());
    CHECK_EQ(run_revisit(detector), 0);
    CHECK(detector.last_error().empty());
    CHECK_EQ(detector.size(), std::size_t{8});
    topoloc_vins::LoopInfo info;
    CHECK(!detector.findConnection(7, 3, info));
    CHECK(!detector.findConnection(6, 0, info));
    CHECK(detector.findConnection(7, 0, info));
    CHECK_EQ(info.cur_index, 7);
    CHECK_EQ(info.old_index, 0);
    const Eigen::Isometry3d truth = revisit_body();
    CHECK((info.relative_t - truth.translation()).norm() < 0.03);
    CHECK(
        Eigen::AngleAxisd(info.relative_q.toRotationMatrix().transpose() * truth.linear()).angle() <
        0.5 * M_PI / 180);
    // The camera turned +3 degrees about its y axis (down): the body turned 3 degrees right.
    CHECK(std::abs(info.relative_yaw - (-3.0)) < 0.5);
    CHECK(info.inliers >= 30);
    CHECK(info.covariance.allFinite() && info.covariance(3, 3) > 0 && info.covariance(0, 0) > 0);
    const Eigen::Matrix<double, 8, 1> packed = info.loop_info();
    CHECK(packed.head<3>() == info.relative_t);
    CHECK(packed[3] == info.relative_q.w() && packed[7] == info.relative_yaw);
}

TEST(vins_gates_refuse_and_log)
{
    topoloc_vins::Config config = test_config();
    config.max_yaw_deg = 1.0; // the revisit turned 3 degrees
    topoloc_vins::LoopDetector detector(image_map(), config);
    std::vector<std::string> log;
    detector.set_logger([&log](const std::string &m) { log.push_back(m); });
    CHECK_EQ(run_revisit(detector), -1);
    CHECK(detector.last_error().empty()); // a refused loop is not an error of the call
    CHECK(!log.empty() && log.back().find("gates") != std::string::npos);
    topoloc_vins::LoopInfo info;
    CHECK(!detector.findConnection(7, 0, info));
}

TEST(bad_keyframes_are_refused_and_change_nothing)
{
    topoloc_vins::LoopDetector detector(image_map(), test_config());
    std::vector<std::string> log;
    detector.set_logger([&log](const std::string &m) { log.push_back(m); });
    const Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();
    CHECK_EQ(detector.detectLoop(keyframe(3, 1, origin, true, false), 3), -1);
    CHECK(detector.last_error().empty());
    auto refused = [&](const topoloc_vins::KeyFrame &kf, int index, const std::string &why) {
        const std::size_t before = log.size();
        CHECK_EQ(detector.detectLoop(kf, index), -1);
        CHECK(detector.last_error().find(why) != std::string::npos);
        CHECK_EQ(log.size(), before + 1);
        CHECK_EQ(detector.size(), std::size_t{1});
    };
    refused(keyframe(2, 2, origin, true, false), 2, "out of order");
    refused(keyframe(3, 2, origin, true, false), 3, "duplicate");
    refused(keyframe(4, 2, origin, true, false), 5, "not frame_index");
    topoloc_vins::KeyFrame nan = keyframe(4, 2, origin, true, false);
    nan.vio_T_w_i.x() = std::numeric_limits<double>::quiet_NaN();
    refused(nan, 4, "non-finite");
    topoloc_vins::KeyFrame sheared = keyframe(4, 2, origin, true, false);
    sheared.vio_R_w_i(0, 1) = 0.3;
    refused(sheared, 4, "not a rotation");
    topoloc_vins::KeyFrame big = keyframe(4, 2, origin, true, false);
    cv::resize(place_image(2), big.image, cv::Size(2 * int(kImgW), 2 * int(kImgH)));
    refused(big, 4, "keyframe 4's image is 320x240, the first keyframe's was 160x120");
    topoloc_vins::KeyFrame lengths = keyframe(4, 2, origin, true, false);
    lengths.point_2d_uv.pop_back();
    refused(lengths, 4, "differ in length");
    topoloc_vins::KeyFrame extra = keyframe(4, 2, origin, true, false);
    extra.keypoints.emplace_back(1.f, 2.f);
    refused(extra, 4, "differ in length");
    topoloc_vins::KeyFrame blank = keyframe(4, 2, origin, false, false);
    blank.image = cv::Mat(int(kImgH), int(kImgW), CV_8UC1, cv::Scalar(128));
    refused(blank, 4, "keyframe 4"); // topoloc: an uninformative image
    topoloc_vins::KeyFrame empty = keyframe(4, 2, origin, false, false);
    empty.image = cv::Mat();
    refused(empty, 4, "8-bit grey or BGR");
    // A logger that throws is contained: the call still returns its -1 and records its error.
    detector.set_logger([](const std::string &) { throw std::runtime_error("logger"); });
    CHECK_EQ(detector.detectLoop(keyframe(3, 2, origin, true, false), 3), -1);
    CHECK(detector.last_error().find("duplicate") != std::string::npos);
    CHECK_EQ(detector.size(), std::size_t{1});
    detector.set_logger([&log](const std::string &m) { log.push_back(m); });
    // After all that, keyframe 4 is taken as if nothing had happened.
    CHECK_EQ(detector.detectLoop(keyframe(4, 2, origin, true, false), 4), -1);
    CHECK(detector.last_error().empty());
    CHECK_EQ(detector.size(), std::size_t{2});
}

TEST(clear_starts_a_new_run)
{
    topoloc_vins::LoopDetector detector(image_map(), test_config());
    CHECK_EQ(run_revisit(detector), 0);
    detector.clear();
    CHECK_EQ(detector.size(), std::size_t{0});
    topoloc_vins::LoopInfo info;
    CHECK(!detector.findConnection(7, 0, info)); // nothing of the old run survives
    CHECK(detector.confirmed().empty());
    // Indices may start again, and the revisit is found again from scratch.
    CHECK_EQ(run_revisit(detector), 0);
    CHECK(detector.findConnection(7, 0, info));
}

// loop_fusion's pose graph as far as loops go: keyframes with has_loop / loop_index,
// `earliest_loop_index`, the optimisation queue, and what optimize4DoF does with them (it takes
// the last index queued, walks keyframes from `earliest_loop_index` to it, and asserts that each
// loop's old index is at or after `earliest_loop_index`).
struct StandInPoseGraph {
    struct Entry {
        bool has_loop = false;
        int loop_index = -1;
    };
    std::map<int, Entry> keyframes;
    int earliest_loop_index = -1;
    std::vector<int> optimize_buf;

    void apply(const topoloc_vins::PoseGraphUpdate &update)
    {
        for (const topoloc_vins::LoopInfo &loop : update.loops)
            keyframes[loop.cur_index] = Entry{true, loop.old_index};
        earliest_loop_index = update.earliest_loop_index;
        if (update.optimize_index >= 0)
            optimize_buf.push_back(update.optimize_index);
    }

    /// The loops optimize4DoF uses, and how many would fire its assert.
    std::pair<std::vector<int>, int> optimize()
    {
        const int cur_index = optimize_buf.empty() ? -1 : optimize_buf.back();
        optimize_buf.clear();
        std::vector<int> used;
        int violations = 0;
        for (const auto &[index, kf] : keyframes) {
            if (index < earliest_loop_index || index > cur_index || !kf.has_loop)
                continue;
            violations += kf.loop_index < earliest_loop_index ? 1 : 0;
            used.push_back(index);
        }
        return {used, violations};
    }
};

// With topoloc's streak of 3, revisits 10 and 11 wait as inconsistent and revisit 12 confirms
// them: the update records all three loops, lowers earliest_loop_index to their old keyframe
// (an earlier loop had set it to 5), and queues the current index once, so optimize4DoF uses
// all three without its assert firing.
TEST(confirmed_loops_keep_the_pose_graph_consistent)
{
    topoloc_vins::Config config = test_config();
    config.options.consistent_keyframes = 3;
    topoloc_vins::LoopDetector detector(image_map(), config);
    StandInPoseGraph graph;
    graph.keyframes[6] = {true, 5}; // a loop recorded before
    graph.earliest_loop_index = 5;
    CHECK_EQ(detector.detectLoop(keyframe(0, 0, Eigen::Isometry3d::Identity(), true, false), 0),
             -1);
    for (int i = 10; i <= 12; ++i) {
        const int loop = detector.detectLoop(keyframe(i, 0, revisit_body(), true, true), i);
        CHECK_EQ(loop, i < 12 ? -1 : 0);
        graph.apply(detector.pose_graph_update(i, loop, graph.earliest_loop_index));
    }
    CHECK(detector.last_error().empty());
    CHECK_EQ(graph.earliest_loop_index, 0);
    const auto [used, violations] = graph.optimize();
    CHECK(used == std::vector<int>({6, 10, 11, 12}));
    CHECK_EQ(violations, 0);
}

// Keyframe `kf` with its points as VINS's normalized coordinates instead of pixels.
topoloc_vins::KeyFrame normalized(topoloc_vins::KeyFrame kf)
{
    const topoloc_vins::Config c = test_config();
    for (const cv::Point2f &uv : kf.point_2d_uv)
        kf.point_2d_norm.emplace_back(float((uv.x - c.cx) / c.fx), float((uv.y - c.cy) / c.fy));
    kf.point_2d_uv.clear();
    return kf;
}

// A second sequence: VINS's new VIO frame (100 m away here) and restarted clock; at the
// default exclusion (50 indices) keyframe 6 of the same sequence could not match keyframe 0.
// The new sequence begins a topoloc session: the loop is found, with its measured pose. The
// points are given as normalized coordinates, and keyframe 0's 3D points are in its origin
// pose, not in its VIO pose shifted since (as VINS's are after a sequence merge).
TEST(a_second_sequence_finds_the_first)
{
    for (const bool second_sequence : {false, true}) {
        topoloc_vins::Config config = test_config();
        config.exclude_recent = 50;
        topoloc_vins::LoopDetector detector(image_map(), config);
        Eigen::Isometry3d shift = Eigen::Isometry3d::Identity();
        shift.translation() = Eigen::Vector3d(100, 0, 0);
        topoloc_vins::KeyFrame first =
            normalized(keyframe(0, 0, shift * Eigen::Isometry3d::Identity(), true, false));
        first.time_stamp = 100;
        first.origin_vio_T = Eigen::Vector3d::Zero();
        first.origin_vio_R = Eigen::Matrix3d::Identity();
        first.sequence = 1;
        CHECK_EQ(detector.detectLoop(first, 0), -1);
        topoloc_vins::KeyFrame revisit = normalized(
            keyframe(6, 0, second_sequence ? revisit_body() : shift * revisit_body(), true, true));
        revisit.time_stamp = second_sequence ? 0.5 : 100.5;
        revisit.sequence = second_sequence ? 2 : 1;
        const int loop = detector.detectLoop(revisit, 6);
        CHECK(detector.last_error().empty());
        CHECK_EQ(loop, second_sequence ? 0 : -1);
        topoloc_vins::LoopInfo info;
        if (!second_sequence || !detector.findConnection(6, 0, info)) {
            CHECK(!second_sequence);
            continue;
        }
        CHECK((info.relative_t - revisit_body().translation()).norm() < 0.03);
        // Within a sequence time must not go back.
        topoloc_vins::KeyFrame earlier = keyframe(7, 1, revisit_body(), false, false);
        earlier.time_stamp = 0.0;
        earlier.sequence = 2;
        CHECK_EQ(detector.detectLoop(earlier, 7), -1);
        CHECK(!detector.last_error().empty());
        CHECK_EQ(detector.size(), std::size_t{2});
    }
}

// VINS fits a loop with the current keyframe's 3D points; the old keyframe may have none (a
// keyframe of a reloaded pose graph has keypoints only). The loop is still metric.
TEST(a_loop_needs_3d_points_on_the_current_keyframe_only)
{
    topoloc_vins::LoopDetector detector(image_map(), test_config());
    topoloc_vins::KeyFrame old = keyframe(0, 0, Eigen::Isometry3d::Identity(), true, false);
    old.keypoints = old.point_2d_uv;
    old.descriptors = old.window_descriptors;
    old.point_3d.clear();
    old.point_2d_uv.clear();
    old.window_descriptors.clear();
    CHECK_EQ(detector.detectLoop(old, 0), -1);
    CHECK_EQ(detector.detectLoop(keyframe(7, 0, revisit_body(), true, true), 7), 0);
    topoloc_vins::LoopInfo info;
    CHECK(detector.findConnection(7, 0, info));
    CHECK((info.relative_t - revisit_body().translation()).norm() < 0.03);
    CHECK(std::abs(info.relative_yaw - (-3.0)) < 0.5);
}

// VINS re-estimates the extrinsics online: each keyframe keeps the ones it was added with, and
// a loop's relative body pose uses both keyframes'. A bad estimate is refused.
TEST(extrinsics_follow_the_online_estimate)
{
    // loop_fusion makes its detector before VINS publishes any extrinsics (qic is zero then):
    // keyframes wait for set_extrinsics.
    topoloc_vins::Config unknown = test_config();
    unknown.qic = Eigen::Matrix3d::Zero();
    topoloc_vins::LoopDetector early(image_map(), unknown);
    CHECK_EQ(early.detectLoop(keyframe(0, 0, Eigen::Isometry3d::Identity(), true, false), 0), -1);
    CHECK(early.last_error().find("no camera extrinsics yet") != std::string::npos);
    CHECK_EQ(early.size(), std::size_t{0});
    CHECK(early.set_extrinsics(Eigen::Vector3d::Zero(), camera_in_body()));
    CHECK_EQ(early.detectLoop(keyframe(0, 0, Eigen::Isometry3d::Identity(), true, false), 0), -1);
    CHECK(early.last_error().empty());
    CHECK_EQ(early.size(), std::size_t{1});

    topoloc_vins::LoopDetector detector(image_map(), test_config());
    CHECK(!detector.set_extrinsics(Eigen::Vector3d(0, 0, std::nan("")), camera_in_body()));
    CHECK(!detector.last_error().empty());
    CHECK(!detector.set_extrinsics(Eigen::Vector3d::Zero(), 2 * camera_in_body()));
    // Keyframe 0 with the configured extrinsics; the revisit after an update that moved the
    // camera 0.1 m along the body's x: the revisit's body is then 0.1 m behind its camera.
    CHECK_EQ(detector.detectLoop(keyframe(0, 0, Eigen::Isometry3d::Identity(), true, false), 0),
             -1);
    const Eigen::Vector3d moved(0.1, 0, 0);
    CHECK(detector.set_extrinsics(moved, camera_in_body()));
    CHECK(detector.last_error().empty());
    Eigen::Isometry3d body_T_camera = Eigen::Isometry3d::Identity();
    body_T_camera.linear() = camera_in_body();
    Eigen::Isometry3d moved_T_camera = body_T_camera;
    moved_T_camera.translation() = moved;
    // The revisit's camera is where revisit_body() put it; its body follows the new extrinsics.
    const Eigen::Isometry3d camera = body_T_camera * second_in_first();
    const Eigen::Isometry3d body = camera * moved_T_camera.inverse();
    topoloc_vins::KeyFrame revisit = keyframe(7, 0, body, true, true);
    CHECK_EQ(detector.detectLoop(revisit, 7), 0);
    topoloc_vins::LoopInfo info;
    CHECK(detector.findConnection(7, 0, info));
    CHECK((info.relative_t - body.translation()).norm() < 0.03);
}

} // namespace

int main() { return run_all_tests(); }
