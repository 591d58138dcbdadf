// Tests of the pose-fix part of the C++ RAII layer (include/topoloc.hpp, ABI 1.6): the options'
// camera fields and the result's `pose_fix`, `Map::keypoint_total` / `view_keypoints` against
// each other and on a map without keypoints, `Map::with_keypoint_points` refusing a wrong length
// with the map still usable, a revisit placed metrically end to end (as test_pose_fix of
// tests/c/test_images.c: a pinhole camera of focal 400 px, the map frame each view's optical
// frame, scene points 1 m away left of the centre and 4 m right of it; the revisit moved the
// content 2 px left, so the fix reprojects the view's scene points 2 px left of their
// keypoints), and bad intrinsics or intrinsics on a map without scene points refused. Built and
// run by tests/cpp/run.sh, normally and under ASan+UBSan.

#include "topoloc.hpp"

#include "harness.hpp"

namespace {

// ---------------------------------------------------------------------------------------------
// Fixtures: the image map of harness.hpp with scene points on two depths
// ---------------------------------------------------------------------------------------------

constexpr double kFocal = 400.0;
constexpr double kCx = (kImgW - 1) / 2.0;
constexpr double kCy = (kImgH - 1) / 2.0;

// Depth of the scene at the keypoint in column `u` of a view: 1 m left of the centre, 4 m right.
double depth_at(float u) { return double(u) < kCx ? 1.0 : 4.0; }

// The scene point of the keypoint at (u, v) in its view's optical frame (= the map frame).
std::array<double, 3> scene_point(float u, float v)
{
    const double d = depth_at(u);
    return {(double(u) - kCx) / kFocal * d, (double(v) - kCy) / kFocal * d, d};
}

// The scene points of every keypoint of `map`, view after view (3 floats per keypoint).
std::vector<float> scene_points(const topoloc::Map &map)
{
    std::vector<float> xyz;
    for (uint32_t view = 0; view < map.view_count(); ++view) {
        const std::vector<float> xy = map.view_keypoints(view);
        for (std::size_t i = 0; i + 1 < xy.size(); i += 2) {
            const std::array<double, 3> p = scene_point(xy[i], xy[i + 1]);
            xyz.insert(xyz.end(), {float(p[0]), float(p[1]), float(p[2])});
        }
    }
    return xyz;
}

// The image map with those scene points attached.
const topoloc::Map &posed_image_map()
{
    static const topoloc::Map map = image_map().with_keypoint_points(scene_points(image_map()));
    return map;
}

// Verification on, the pinhole camera above, fixes from 12 inliers.
topoloc::LocalizerOptions camera_options()
{
    topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    options.verify_candidates = 3;
    options.camera_fx = kFocal;
    options.camera_fy = kFocal;
    options.camera_cx = kCx;
    options.camera_cy = kCy;
    options.pose_min_inliers = 12;
    return options;
}

// The revisit of place 4 (as the C test: seed 204).
const std::vector<uint8_t> &revisit_of_place_4()
{
    static const std::vector<uint8_t> px = revisit_pixels(places_pixels()[4], 204);
    return px;
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

TEST(pose_fix_defaults)
{
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 6, "pose fixes are ABI 1.6");
    CHECK(topoloc_abi_version_minor() >= 6); // the loaded library has them too
    const topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    CHECK_EQ(options.struct_size, sizeof(topoloc::LocalizerOptions));
    CHECK(options.camera_fx == 0.0); // no camera
    CHECK_EQ(options.pose_min_inliers, uint32_t{30});
    const topoloc::Result result;
    CHECK(!result.pose_fix.has_value());
    const topoloc::PoseFix fix;
    CHECK(fix.view == 0 && fix.inliers == 0);
}

TEST(off_map_evidence_options)
{
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 9, "off-map evidence from verification is ABI 1.9");
    CHECK(topoloc_abi_version_minor() >= 9);
    topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    CHECK(options.verify_off_map_inliers < 0.0); // the map's feature kind's threshold
    CHECK(options.verify_off_map_inlier_scale == 4.0);
    options.verify_candidates = 2;
    options.verify_off_map_inlier_scale = -1.0;
    bool refused = false;
    try {
        topoloc::Localizer localizer(image_map(), options);
    } catch (const topoloc::Error &e) {
        refused = e.status() == TOPOLOC_ERR_INVALID_OPTION &&
                  std::string(e.what()).find("off_map_inlier_scale") != std::string::npos;
    }
    CHECK(refused);
}

TEST(map_keypoints)
{
    const topoloc::Map &map = image_map();
    const std::size_t total = map.keypoint_total();
    CHECK(total > 0);
    std::size_t sum = 0;
    for (uint32_t view = 0; view < map.view_count(); ++view) {
        const std::vector<float> xy = map.view_keypoints(view);
        CHECK(xy.size() % 2 == 0);
        CHECK(!xy.empty()); // every place image is textured
        for (std::size_t i = 0; i + 1 < xy.size(); i += 2) {
            CHECK(xy[i] >= 0.f && xy[i] <= float(kImgW - 1));
            CHECK(xy[i + 1] >= 0.f && xy[i + 1] <= float(kImgH - 1));
        }
        sum += xy.size() / 2;
        // The C call agrees on the count (and wants 2 floats per keypoint).
        std::size_t count = 0;
        CHECK(topoloc_map_view_keypoints(map.capi(), view, nullptr, 0, &count) ==
              (xy.empty() ? TOPOLOC_OK : TOPOLOC_ERR_BUFFER_TOO_SMALL));
        CHECK_EQ(count, xy.size() / 2);
    }
    CHECK_EQ(sum, total);
    std::printf("    %zu keypoints in %zu views\n", total, map.view_count());
    CHECK_THROWS_STATUS(map.view_keypoints(uint32_t(map.view_count())), TOPOLOC_ERR_UNKNOWN_VIEW);

    // A map from descriptors stores no keypoints: a total of 0, and the typed error per view.
    const topoloc::Map chain = chain_map();
    CHECK_EQ(chain.keypoint_total(), std::size_t{0});
    const std::string message =
        CHECK_THROWS_STATUS(chain.view_keypoints(0), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(message.find("keypoints") != std::string::npos);
    CHECK_THROWS_STATUS(chain.with_keypoint_points(std::vector<float>()),
                        TOPOLOC_ERR_INVALID_ARGUMENT);

    // An empty owner throws NULL_ARGUMENT instead of crashing.
    const topoloc::Map empty;
    CHECK_THROWS_STATUS(empty.keypoint_total(), TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK_THROWS_STATUS(empty.view_keypoints(0), TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK_THROWS_STATUS(empty.with_keypoint_points(std::vector<float>()),
                        TOPOLOC_ERR_NULL_ARGUMENT);
}

TEST(with_keypoint_points_refusals)
{
    const topoloc::Map &map = image_map();
    const std::size_t total = map.keypoint_total();
    const std::vector<float> first_view = map.view_keypoints(0);
    std::vector<float> xyz = scene_points(map);
    CHECK_EQ(xyz.size(), 3 * total);

    // The wrong length (one point short, one float over): refused, naming what is needed.
    std::vector<float> short_by_one(xyz.begin(), xyz.end() - 3);
    const std::string message =
        CHECK_THROWS_STATUS(map.with_keypoint_points(short_by_one), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(message.find("keypoints need") != std::string::npos);
    CHECK(message.find(std::to_string(3 * total)) != std::string::npos);
    std::vector<float> one_over = xyz;
    one_over.push_back(1.f);
    CHECK_THROWS_STATUS(map.with_keypoint_points(one_over), TOPOLOC_ERR_INVALID_ARGUMENT);
    // A point neither finite nor all NaN.
    std::vector<float> half_nan = xyz;
    half_nan[1] = std::numeric_limits<float>::quiet_NaN();
    CHECK_THROWS_STATUS(map.with_keypoint_points(half_nan), TOPOLOC_ERR_INVALID_ARGUMENT);

    // The map is unchanged and usable: same keypoints, and a localizer on it still verifies.
    CHECK_EQ(map.keypoint_total(), total);
    CHECK(map.view_keypoints(0) == first_view);
    topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    options.verify_candidates = 3;
    topoloc::Localizer localizer(map, options);
    const topoloc::Result &r = localizer.process(gray(revisit_of_place_4()), 0.0);
    CHECK(r.place == 4 && r.verified && r.inliers >= 20);
    CHECK(!r.pose_fix); // no camera

    // All-NaN points (unknown) are accepted; the copy is an owner of its own, with the same
    // keypoints, and outlives the map it was made from.
    xyz[0] = xyz[1] = xyz[2] = std::numeric_limits<float>::quiet_NaN();
    topoloc::Map copy = map.with_keypoint_points(xyz);
    CHECK(static_cast<bool>(copy) && copy.capi() != map.capi());
    topoloc::Map second = copy.with_keypoint_points(xyz);
    copy = topoloc::Map(); // frees the first copy (ASan: the second must not depend on it)
    CHECK_EQ(second.keypoint_total(), total);
    CHECK(second.view_keypoints(0) == first_view);
    CHECK_EQ(second.view_count(), map.view_count());
}

TEST(pose_fix_of_a_revisit)
{
    const topoloc::Map &posed = posed_image_map();
    topoloc::Localizer localizer(posed, camera_options());
    const topoloc::Result &r = localizer.process(gray(revisit_of_place_4()), 0.0);
    CHECK_EQ(r.place, uint32_t{4});
    CHECK(r.verified);
    CHECK(r.pose_fix.has_value());
    if (!r.pose_fix) {
        std::printf("    no pose fix: place %u, view %u, verified %d, %u inliers\n", r.place,
                    r.view, int(r.verified), r.inliers);
        return;
    }
    const topoloc::PoseFix fix = *r.pose_fix; // a copy: the result is overwritten below
    const topoloc::Pose &T = fix.world_T_camera;
    std::printf("    revisit of place 4: pose fix against view %u, %u inliers (verification %u), "
                "t = %.3f %.3f %.3f\n",
                fix.view, fix.inliers, r.inliers, T[3], T[7], T[11]);
    CHECK(fix.inliers >= 12);
    CHECK_EQ(posed.view_info(fix.view).place, uint32_t{4});
    // Rigid: an orthonormal rotation and the bottom row 0 0 0 1.
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            const double d =
                T[4 * i] * T[4 * j] + T[4 * i + 1] * T[4 * j + 1] + T[4 * i + 2] * T[4 * j + 2];
            CHECK(std::abs(d - (i == j ? 1.0 : 0.0)) < 1e-6);
        }
    CHECK(T[12] == 0.0 && T[13] == 0.0 && T[14] == 0.0 && T[15] == 1.0);

    // The fixed camera sees the view's scene points 2 px left of their keypoints (the revisit's
    // shift): camera_T_world = inverse of world_T_camera, x_c = R^T (X - t), then the pinhole.
    const std::vector<float> xy = posed.view_keypoints(fix.view);
    std::vector<double> errors;
    std::size_t behind = 0;
    for (std::size_t i = 0; i + 1 < xy.size(); i += 2) {
        const std::array<double, 3> X = scene_point(xy[i], xy[i + 1]);
        const double d[3] = {X[0] - T[3], X[1] - T[7], X[2] - T[11]};
        double c[3];
        for (int k = 0; k < 3; ++k)
            c[k] = T[k] * d[0] + T[4 + k] * d[1] + T[8 + k] * d[2];
        if (c[2] <= 0.1) {
            ++behind;
            continue;
        }
        const double du = kCx + kFocal * c[0] / c[2] - (double(xy[i]) - 2.0);
        const double dv = kCy + kFocal * c[1] / c[2] - double(xy[i + 1]);
        errors.push_back(std::sqrt(du * du + dv * dv));
    }
    CHECK_EQ(behind, std::size_t{0});
    CHECK(!errors.empty());
    if (!errors.empty()) {
        std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
        const double median = errors[errors.size() / 2];
        std::printf(
            "    median reprojection error against the 2 px shift: %.3f px over %zu points\n",
            median, errors.size());
        CHECK(median < 1.5);
    }

    // The fix is part of the last result until reset, which clears it.
    CHECK(localizer.last_result().pose_fix.has_value());
    localizer.reset();
    CHECK(!localizer.last_result().pose_fix);

    // The very image of place 6: if fixed, then against place 6's view and where that view's
    // camera was (the map frame is each view's optical frame).
    const topoloc::Result &other = localizer.process(gray(places_pixels()[6]), 0.0);
    CHECK_EQ(other.place, uint32_t{6});
    if (other.pose_fix) {
        const topoloc::Pose &S = other.pose_fix->world_T_camera;
        std::printf(
            "    image of place 6: pose fix against view %u, %u inliers, t = %.3f %.3f %.3f\n",
            other.pose_fix->view, other.pose_fix->inliers, S[3], S[7], S[11]);
        CHECK_EQ(posed.view_info(other.pose_fix->view).place, uint32_t{6});
        CHECK(std::abs(S[3]) < 0.05 && std::abs(S[7]) < 0.05 && std::abs(S[11]) < 0.05);
        CHECK(S[0] > 0.999 && S[5] > 0.999 && S[10] > 0.999);
    }

    // The same posed map without a camera: verified, but no fix.
    topoloc::LocalizerOptions no_camera = camera_options();
    no_camera.camera_fx = 0.0;
    topoloc::Localizer plain(posed, no_camera);
    const topoloc::Result &unposed = plain.process(gray(revisit_of_place_4()), 0.0);
    CHECK(unposed.place == 4 && unposed.verified);
    CHECK(!unposed.pose_fix);
}

TEST(camera_option_refusals)
{
    topoloc::LocalizerOptions options = camera_options();
    options.camera_fx = -400.0;
    CHECK(CHECK_THROWS_STATUS(topoloc::Localizer(posed_image_map(), options),
                              TOPOLOC_ERR_INVALID_OPTION)
              .find("fx") != std::string::npos);
    options = camera_options();
    options.camera_cy = std::numeric_limits<double>::quiet_NaN();
    CHECK(CHECK_THROWS_STATUS(topoloc::Localizer(posed_image_map(), options),
                              TOPOLOC_ERR_INVALID_OPTION)
              .find("cy") != std::string::npos);
    options = camera_options();
    options.pose_min_inliers = 5; // below the 6 a pose needs
    CHECK_THROWS_STATUS(topoloc::Localizer(posed_image_map(), options), TOPOLOC_ERR_INVALID_OPTION);

    // A camera on a map whose keypoints have no scene points.
    const std::string message = CHECK_THROWS_STATUS(
        topoloc::Localizer(image_map(), camera_options()), TOPOLOC_ERR_INVALID_OPTION);
    CHECK(message.find("scene points") != std::string::npos);

    // The options as they are work on the posed map.
    const topoloc::Localizer localizer(posed_image_map(), camera_options());
    CHECK(static_cast<bool>(localizer));
}

} // namespace

int main() { return run_all_tests(); }
