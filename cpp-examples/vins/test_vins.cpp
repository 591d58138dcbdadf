// Tests of the VINS adapter (topoloc_vins.hpp): a revisit gives detectLoop's old index and the
// loop_info VINS's findConnection would give (relative t, q, yaw in the body frames), VINS's
// gates refuse what they would refuse, and bad keyframes (out of order, duplicate, NaN pose,
// another image size, arrays of different lengths, use after clear) give a logged error, no
// loop and an unchanged detector, also when the logger throws. Images: the textured places of tests/cpp/harness.hpp (their
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

} // namespace

int main() { return run_all_tests(); }
