// Tests of image keyframes in the C++ RAII layer (include/topoloc/keyframes.hpp and
// `LoopDetector::add_image` / `candidates`, ABI 1.15), as tests/c/test_loop_images.c: the
// `KeyframeDescriber` options, moves and errors; a VLAD-ORB map of small grey places whose
// revisits (shifted by 2 pixels), added as images, close a loop each with candidates ranked by
// inliers, while bad keyframes, images and depth throw and change nothing; and, with the cache's
// models (required when CI is "true"), the learned path: an ONNX map with XFeat keypoints as the
// first session and XFeat image keyframes whose hints carry a pose. Built and run by
// tests/cpp/run.sh, normally and under ASan+UBSan.

#include "topoloc.hpp"

#include "harness.hpp"

#include <cstdlib>
#include <unistd.h> // access (POSIX)

namespace {

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

// Loop options for the small grey places: every place may close a loop at once.
topoloc::LoopOptions image_loop_options(uint32_t min_inliers)
{
    topoloc::LoopOptions options = topoloc::default_loop_options();
    options.exclude_recent_ids = 1;
    options.exclude_recent_s = 0.0;
    options.candidate_id_gap = 0;
    options.consistent_keyframes = 1;
    options.min_inliers = min_inliers;
    options.odometry_gate = false;
    return options;
}

// The intrinsics of the 160x120 places (a 150-pixel focal length).
topoloc::LoopOptions with_intrinsics(topoloc::LoopOptions options)
{
    options.fx = 150.0;
    options.fy = 150.0;
    options.cx = 79.5;
    options.cy = 59.5;
    return options;
}

// A keyframe with only an id and a timestamp (the image gives the rest).
topoloc::LoopKeyframe image_keyframe(uint64_t id)
{
    topoloc::LoopKeyframe k;
    k.id = id;
    k.timestamp = double(id);
    return k;
}

// Adds place p's image (first pass) or its revisit (second pass) as keyframe `id`.
topoloc::LoopHint add_place(topoloc::LoopDetector &detector, topoloc::KeyframeDescriber &describer,
                            uint32_t p, bool revisit, uint64_t id)
{
    const std::vector<uint8_t> px =
        revisit ? revisit_pixels(places_pixels()[p], 300u + p) : places_pixels()[p];
    return detector.add_image(describer, image_keyframe(id), gray(px));
}

topoloc::KeyframeDescriber orb_describer(const topoloc::Map &map)
{
    topoloc::KeyframeDescriberOptions options = topoloc::default_keyframe_describer_options();
    options.local_features = topoloc::to_c(topoloc::LocalFeatures::Orb);
    return topoloc::KeyframeDescriber(map, options);
}

// The path of a model of the cache (`$TOPOLOC_CACHE/<file>`, else `~/.cache/topoloc/<file>`), or
// nullopt when it is missing: then the checks are skipped with a note, which fails the test when
// CI is "true" (as models_ready of tests/c/harness.c).
std::optional<std::string> cached_model(const std::string &file, const char *checks)
{
    const char *cache = std::getenv("TOPOLOC_CACHE");
    const char *home = std::getenv("HOME");
    const char *ci = std::getenv("CI");
    const std::string path =
        cache != nullptr && cache[0] != '\0'
            ? std::string(cache) + "/" + file
            : std::string(home != nullptr ? home : "") + "/.cache/topoloc/" + file;
    if (access(path.c_str(), R_OK) != 0) {
        if (ci != nullptr && std::string(ci) == "true")
            report_failure(__FILE__, __LINE__, "CI is \"true\": the models are required");
        std::printf("    %s checks skipped: no model at %s (run scripts/setup-models.sh)\n", checks,
                    path.c_str());
        return std::nullopt;
    }
    return path;
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

TEST(local_features_and_option_defaults)
{
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 15, "image keyframes are ABI 1.15");
    static_assert(
        std::is_same_v<std::underlying_type_t<topoloc::LocalFeatures>, topoloc_local_features>);
    static_assert(topoloc::to_c(topoloc::LocalFeatures::Orb) == TOPOLOC_LOCAL_FEATURES_ORB);
    static_assert(topoloc::to_c(topoloc::LocalFeatures::XFeat) == TOPOLOC_LOCAL_FEATURES_XFEAT);
    static_assert(topoloc::to_c(topoloc::LocalFeatures::Cells) == TOPOLOC_LOCAL_FEATURES_CELLS);
    static_assert(
        std::is_same_v<topoloc::KeyframeDescriberOptions, topoloc_keyframe_describer_options>);
    static_assert(std::is_same_v<topoloc::LoopCandidateCheck, topoloc_loop_candidate_check>);
    static_assert(std::is_same_v<topoloc::DepthImage, topoloc_depth_image>);

    const topoloc::KeyframeDescriberOptions options = topoloc::default_keyframe_describer_options();
    CHECK_EQ(options.struct_size, sizeof(topoloc::KeyframeDescriberOptions));
    CHECK(options.local_features == topoloc::to_c(topoloc::LocalFeatures::XFeat));
    CHECK(options.backend == TOPOLOC_BACKEND_AUTO);
    CHECK(options.onnx_model_path == nullptr && options.onnx_runtime_path == nullptr &&
          options.xfeat_model_path == nullptr);
    CHECK_EQ(options.xfeat_max_pixels, uint32_t{160000});
    CHECK_EQ(options.threads, uint32_t{1});

    // Image maps store 500 XFeat keypoints per view unless told otherwise, the model from the
    // cache.
    const topoloc::ImageMapOptions map_options = topoloc::default_image_map_options();
    CHECK_EQ(map_options.verification_keypoints, uint32_t{500});
    CHECK(map_options.local_features == TOPOLOC_LOCAL_FEATURES_XFEAT &&
          map_options.xfeat_model_path == nullptr);

    // depth_view borrows what it is given.
    const std::vector<uint16_t> values(12, 1000);
    const topoloc::DepthImage depth = topoloc::depth_view(values, 1000.0);
    CHECK(depth.values == values.data() && depth.values_len == 12 &&
          depth.units_per_metre == 1000.0);
}

TEST(keyframe_describer_owns_and_refuses_what_it_cannot_honour)
{
    static_assert(!std::is_copy_constructible_v<topoloc::KeyframeDescriber>);
    static_assert(!std::is_copy_assignable_v<topoloc::KeyframeDescriber>);
    static_assert(std::is_nothrow_move_constructible_v<topoloc::KeyframeDescriber>);
    static_assert(std::is_nothrow_move_assignable_v<topoloc::KeyframeDescriber>);
    static_assert(!std::is_convertible_v<topoloc::KeyframeDescriber, bool>,
                  "operator bool must be explicit");
    static_assert(
        std::is_base_of_v<
            topoloc::detail::Owner<topoloc_keyframe_describer, &topoloc_keyframe_describer_free>,
            topoloc::KeyframeDescriber>);

    const topoloc::Map &map = image_map();
    topoloc::KeyframeDescriber a = orb_describer(map);
    CHECK(static_cast<bool>(a));
    CHECK(a.local_features() == topoloc::LocalFeatures::Orb);
    const topoloc_keyframe_describer *raw = a.capi();

    topoloc::KeyframeDescriber b(std::move(a)); // move construction
    CHECK(!a && a.capi() == nullptr && b.capi() == raw);
    CHECK_THROWS_STATUS(a.local_features(), TOPOLOC_ERR_NULL_ARGUMENT);
    topoloc::KeyframeDescriber c = orb_describer(map);
    c = std::move(b); // move assignment over a live describer frees the old one (ASan)
    CHECK(!b && c.capi() == raw);
    assign_from(c, c); // self-move-assignment keeps the describer
    CHECK(c.capi() == raw && c.local_features() == topoloc::LocalFeatures::Orb);
    topoloc_keyframe_describer *released = c.release(); // C code frees it
    CHECK(!c && released == raw);
    topoloc_keyframe_describer_free(released);
    CHECK(!topoloc::KeyframeDescriber(nullptr));

    // A map built from descriptors stores no describer.
    try {
        (void)orb_describer(chain_map());
        CHECK(false);
    } catch (const topoloc::NoDescriberError &e) {
        CHECK(e.status() == TOPOLOC_ERR_NO_DESCRIBER);
    }
    CHECK_THROWS_STATUS(orb_describer(topoloc::Map()), TOPOLOC_ERR_NULL_ARGUMENT);

    topoloc::KeyframeDescriberOptions options = topoloc::default_keyframe_describer_options();
    options.local_features = 99;
    CHECK(
        CHECK_THROWS_STATUS((topoloc::KeyframeDescriber{map, options}), TOPOLOC_ERR_INVALID_OPTION)
            .find("TOPOLOC_LOCAL_FEATURES_") != std::string::npos);
    // Dense cells come from a CNN's feature map: the map is VLAD.
    options.local_features = topoloc::to_c(topoloc::LocalFeatures::Cells);
    CHECK_THROWS_STATUS((topoloc::KeyframeDescriber{map, options}), TOPOLOC_ERR_INVALID_OPTION);
    // A missing XFeat model names the path tried.
    TempDir dir;
    const std::string missing = (dir.path / "no-such-xfeat.onnx").string();
    options.local_features = topoloc::to_c(topoloc::LocalFeatures::XFeat);
    options.xfeat_model_path = missing.c_str();
    try {
        (void)topoloc::KeyframeDescriber(map, options);
        CHECK(false);
    } catch (const topoloc::BackendUnavailableError &e) {
        CHECK(e.status() == TOPOLOC_ERR_BACKEND_UNAVAILABLE);
        CHECK(e.message().find(missing) != std::string::npos);
    }
    options = topoloc::default_keyframe_describer_options();
    options.local_features = topoloc::to_c(topoloc::LocalFeatures::Orb);
    options.threads = 0;
    CHECK_THROWS_STATUS((topoloc::KeyframeDescriber{map, options}), TOPOLOC_ERR_INVALID_OPTION);
    options.threads = 1;
    options.struct_size = 3;
    CHECK_THROWS_STATUS((topoloc::KeyframeDescriber{map, options}), TOPOLOC_ERR_STRUCT_SIZE);
}

TEST(image_keyframes_close_loops_with_ranked_candidates)
{
    const topoloc::Map &map = image_map();
    topoloc::KeyframeDescriber describer = orb_describer(map);
    topoloc::LoopDetector detector =
        topoloc::LoopDetector::for_descriptors_of(map, image_loop_options(12));
    CHECK(detector.candidates().empty()); // nothing added yet

    for (uint32_t p = 0; p < kImgPlaces; ++p) {
        const topoloc::LoopHint hint = add_place(detector, describer, p, false, p);
        CHECK_EQ(hint.query_id, uint64_t{p});
    }
    unsigned closed = 0;
    for (uint32_t p = 0; p < kImgPlaces; ++p) {
        const topoloc::LoopHint hint = add_place(detector, describer, p, true, 100u + p);
        closed += hint.accepted && hint.matched_id == p;
        CHECK(!hint.accepted || hint.matched_id == p);
        const std::vector<topoloc::LoopCandidateCheck> checks = detector.candidates();
        CHECK(!checks.empty() && checks.size() <= 8);
        for (std::size_t i = 1; i < checks.size(); ++i)
            CHECK(checks[i].inliers <= checks[i - 1].inliers);
        if (!checks.empty() && hint.has_match) {
            // The hint's candidate is among them (refinement may pick a neighbour of it).
            CHECK(checks[0].inliers >= 12 && checks[0].confidence > 0.f &&
                  checks[0].confidence <= 1.f && checks[0].similarity > -1.f);
            CHECK(checks[0].keyframe_id < kImgPlaces);
        }
    }
    std::printf("    image keyframes closed %u/%u loops (ORB)\n", closed, unsigned{kImgPlaces});
    CHECK(closed >= kImgPlaces - 1);
    const std::vector<topoloc::LoopCandidateCheck> last = detector.candidates();
    CHECK_EQ(detector.candidates(1).size(), std::size_t{1});
    CHECK(detector.candidates(0).empty());
    CHECK_EQ(detector.candidates(std::numeric_limits<std::size_t>::max()).size(),
             detector.candidates(detector.size()).size());
    CHECK_EQ(detector.size(), std::size_t{2 * kImgPlaces});

    // Bad keyframes, images and depth: each throws, and the detector and its last candidates
    // are unchanged.
    const std::vector<uint8_t> &px = places_pixels()[0];
    topoloc::LoopKeyframe bad = image_keyframe(500);
    bad.descriptor = {1.f, 0.f, 0.f, 0.f};
    CHECK(CHECK_THROWS_STATUS(detector.add_image(describer, bad, gray(px)),
                              TOPOLOC_ERR_INVALID_ARGUMENT)
              .find("come from the image") != std::string::npos);
    bad = image_keyframe(500);
    bad.keypoints = two_views().first;
    bad.keypoint_descriptors = two_views().descriptors;
    CHECK_THROWS_STATUS(detector.add_image(describer, bad, gray(px)), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_THROWS_STATUS(detector.add_image(describer, image_keyframe(50), gray(px)),
                        TOPOLOC_ERR_INVALID_ARGUMENT); // below the last id
    try {
        (void)detector.add_image(describer, image_keyframe(500), topoloc::Image{});
        CHECK(false);
    } catch (const topoloc::InvalidImageError &e) {
        CHECK(e.status() == TOPOLOC_ERR_INVALID_IMAGE);
    }
    const std::vector<uint8_t> flat(kImgW * kImgH, 128);
    try {
        (void)detector.add_image(describer, image_keyframe(500), gray(flat));
        CHECK(false);
    } catch (const topoloc::UninformativeImageError &e) {
        CHECK(e.status() == TOPOLOC_ERR_UNINFORMATIVE_IMAGE);
    }
    topoloc::KeyframeDescriber empty;
    CHECK(CHECK_THROWS_STATUS(detector.add_image(empty, image_keyframe(500), gray(px)),
                              TOPOLOC_ERR_NULL_ARGUMENT)
              .find("describer") != std::string::npos);
    // Depth needs intrinsics.
    const std::vector<uint16_t> depth(kImgW * kImgH, 2000);
    CHECK(CHECK_THROWS_STATUS(detector.add_image(describer, image_keyframe(500), gray(px),
                                                 topoloc::depth_view(depth, 1000.0)),
                              TOPOLOC_ERR_INVALID_OPTION)
              .find("intrinsics") != std::string::npos);
    CHECK_EQ(detector.size(), std::size_t{2 * kImgPlaces});
    const std::vector<topoloc::LoopCandidateCheck> kept = detector.candidates();
    CHECK_EQ(kept.size(), last.size());
    for (std::size_t i = 0; i < kept.size() && i < last.size(); ++i)
        CHECK(kept[i].keyframe_id == last[i].keyframe_id && kept[i].inliers == last[i].inliers);

    // An empty vector that still owns storage is "not given": the keyframe is taken.
    topoloc::LoopKeyframe reused = image_keyframe(500);
    reused.descriptor.assign(8, 1.f);
    reused.descriptor.clear();
    (void)detector.add_image(describer, reused, gray(revisit_pixels(px, 7)));
    CHECK_EQ(detector.size(), std::size_t{2 * kImgPlaces + 1});

    // An empty detector throws.
    topoloc::LoopDetector none;
    CHECK_THROWS_STATUS(none.candidates(), TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK_THROWS_STATUS(none.add_image(describer, image_keyframe(600), gray(px)),
                        TOPOLOC_ERR_NULL_ARGUMENT);
}

TEST(image_keyframes_with_depth_and_c_records)
{
    const topoloc::Map &map = image_map();
    topoloc::KeyframeDescriber describer = orb_describer(map);
    topoloc::LoopDetector detector =
        topoloc::LoopDetector::for_descriptors_of(map, with_intrinsics(image_loop_options(12)));
    const std::vector<uint8_t> &px = places_pixels()[0];
    std::vector<uint16_t> depth(kImgW * kImgH - 1, 2000);

    // A depth image of another size than the image is refused; the right size is taken.
    CHECK(CHECK_THROWS_STATUS(detector.add_image(describer, image_keyframe(1), gray(px),
                                                 topoloc::depth_view(depth, 1000.0)),
                              TOPOLOC_ERR_INVALID_ARGUMENT)
              .find("depth.values_len") != std::string::npos);
    CHECK_EQ(detector.size(), std::size_t{0});
    depth.push_back(2000);
    const topoloc::LoopHint first = detector.add_image(describer, image_keyframe(1), gray(px),
                                                       topoloc::depth_view(depth, 1000.0));
    CHECK(!first.has_match && first.query_id == 1);
    CHECK_EQ(detector.size(), std::size_t{1});
    // A depth view without values is no depth.
    (void)detector.add_image(describer, image_keyframe(2), gray(places_pixels()[1]),
                             topoloc::depth_view(nullptr, 0, 0.0));
    CHECK_EQ(detector.size(), std::size_t{2});

    // The C record overload: the revisit of place 0, against the keyframe that has depth.
    topoloc_loop_keyframe raw;
    CHECK(topoloc_loop_keyframe_default(&raw) == TOPOLOC_OK);
    raw.id = 10;
    raw.timestamp = 10.0;
    const std::vector<uint8_t> revisit = revisit_pixels(px, 300u);
    raw.struct_size = 3;
    CHECK_THROWS_STATUS(detector.add_image(describer, raw, gray(revisit)), TOPOLOC_ERR_STRUCT_SIZE);
    raw.struct_size = sizeof raw;
    const topoloc::LoopHint hint = detector.add_image(describer, raw, gray(revisit));
    CHECK(hint.query_id == 10 && hint.has_match && hint.matched_id == 1);
    CHECK(!hint.has_pose || hint.scale_known); // the matched keyframe's points have depth
    std::printf("    ORB revisit of a keyframe with depth: accepted %d, pose %d, metric %d, "
                "%u inliers\n",
                int(hint.accepted), int(hint.has_pose), int(hint.scale_known),
                unsigned(hint.inliers));
    const std::vector<topoloc::LoopCandidateCheck> checks = detector.candidates();
    CHECK(!checks.empty() && checks.size() <= 2);
    if (!checks.empty())
        CHECK(checks[0].keyframe_id == 1 && checks[0].place == hint.place);
}

// The learned path: an ONNX map with XFeat keypoints (ABI 1.15 map options) is the first
// session; XFeat image keyframes of the revisits close loops against it with a pose.
TEST(the_learned_path_closes_loops_with_poses_against_an_xfeat_map)
{
    if (!cached_model("models/mobilenetv2-mlf-int8.onnx", "learned loop") ||
        !cached_model("models/xfeat.onnx", "learned loop"))
        return;
    constexpr uint32_t kPlacesX = 6;
    const std::vector<topoloc::Image> images = place_images(kPlacesX);
    topoloc::ImageMapOptions options = topoloc::default_image_map_options();
    options.backend = TOPOLOC_BACKEND_ONNX;
    options.dim = kPlacesX - 1;
    options.threads = 1;
    options.local_features = 77;
    CHECK_THROWS_STATUS(topoloc::Map::build_from_images(images, options),
                        TOPOLOC_ERR_INVALID_OPTION);
    options.local_features = topoloc::to_c(topoloc::LocalFeatures::XFeat);
    options.verification_keypoints = 256;
    const topoloc::Map map = topoloc::Map::build_from_images(images, options);
    CHECK_EQ(map.view_count(), std::size_t{kPlacesX});
    CHECK(map.keypoint_total() > 0 && map.keypoint_total() <= 256 * kPlacesX);

    topoloc::KeyframeDescriber describer(map); // default options: XFeat
    CHECK(describer.local_features() == topoloc::LocalFeatures::XFeat);
    topoloc::LoopDetector detector =
        topoloc::LoopDetector::from_map(map, with_intrinsics(image_loop_options(30)));
    CHECK_EQ(detector.size(), std::size_t{kPlacesX});
    unsigned closed = 0, posed = 0, rotation_only = 0;
    for (uint32_t p = 0; p < kPlacesX; ++p) {
        const topoloc::LoopHint hint = add_place(detector, describer, p, true, 100u + p);
        closed += hint.accepted && hint.matched_id == p;
        posed += hint.accepted && hint.has_pose;
        CHECK(!hint.accepted || hint.matched_id == p);
        if (hint.accepted) {
            const std::vector<topoloc::LoopCandidateCheck> checks = detector.candidates();
            CHECK(!checks.empty() && checks[0].inliers >= 30);
        }
        if (hint.accepted && hint.has_pose) {
            // A 2-pixel shift is a turn of atan(2 / 150) = 0.76 degrees: unscaled, with a zero
            // translation (rotation only) or a unit direction.
            const topoloc::Pose &T = hint.matched_T_query;
            const double t = std::sqrt(T[3] * T[3] + T[7] * T[7] + T[11] * T[11]);
            const double turn =
                std::acos(std::min(1.0, (T[0] + T[5] + T[10] - 1.0) / 2.0)) * 57.29577951308232;
            CHECK(!hint.scale_known && (t == 0.0 || std::abs(t - 1.0) < 1e-6));
            CHECK(turn < 2.0);
            rotation_only += t == 0.0;
        }
    }
    std::printf("    XFeat image keyframes closed %u/%u loops, %u with a pose (%u rotation only)\n",
                closed, unsigned{kPlacesX}, posed, rotation_only);
    CHECK(closed >= kPlacesX - 1 && posed == closed);

    // ORB keyframes cannot join a detector whose keyframes have XFeat features.
    topoloc::KeyframeDescriber orb = orb_describer(map);
    CHECK_THROWS_STATUS(detector.add_image(orb, image_keyframe(200), gray(places_pixels()[0])),
                        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_EQ(detector.size(), std::size_t{2 * kPlacesX});
}

} // namespace

int main() { return run_all_tests(); }
