// Tests of the loop closure part of the C++ RAII layer (include/topoloc.hpp, ABI 1.5):
// `LoopDetector` ownership and moves, `default_loop_options`, the `Gate` codes, a keyframe and
// its revisit from another pose turning into an accepted hint (as test_loop_closure of
// tests/c/test_loops.c), bad keyframes throwing with the detector unchanged, relocalization
// queries, a metric hint with intrinsics and scene points, and a second session from the saved
// map. Built and run by tests/cpp/run.sh, normally and under ASan+UBSan.

#include "topoloc.hpp"

#include "harness.hpp"

namespace {

// ---------------------------------------------------------------------------------------------
// Fixtures: descriptors and keyframes over the two views of harness.hpp
// ---------------------------------------------------------------------------------------------

constexpr uint32_t kLoopDim = 8;

// The global descriptor of scene `scene` (as loop_descriptor of the C test).
std::vector<float> loop_descriptor(uint32_t scene)
{
    std::vector<float> d(kLoopDim);
    for (uint32_t i = 0; i < kLoopDim; ++i)
        d[i] = i == scene % kLoopDim ? 1.0f : 0.05f * float(i);
    return d;
}

// A keyframe of scene 1 seen from the first (`revisit` false) or the second camera.
topoloc::LoopKeyframe keyframe(uint64_t id, double timestamp, bool revisit)
{
    topoloc::LoopKeyframe k;
    k.id = id;
    k.timestamp = timestamp;
    k.descriptor = loop_descriptor(1);
    k.keypoints = revisit ? two_views().second : two_views().first;
    k.keypoint_descriptors = two_views().descriptors;
    return k;
}

// The C test's options: a short exclusion window and no consistency wait.
topoloc::LoopOptions test_options()
{
    topoloc::LoopOptions options = topoloc::default_loop_options();
    options.exclude_recent_ids = 5;
    options.exclude_recent_s = 0.0;
    options.consistent_keyframes = 1;
    return options;
}

topoloc::LoopDetector test_detector()
{
    return topoloc::LoopDetector::create("test", "loops", kLoopDim, test_options());
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

TEST(loop_options_and_gates)
{
    CHECK(topoloc::abi_version() >= TOPOLOC_ABI_VERSION);
    const topoloc::LoopOptions options = topoloc::default_loop_options();
    CHECK_EQ(options.struct_size, sizeof(topoloc::LoopOptions));
    CHECK_EQ(options.candidates, uint32_t{5});
    CHECK_EQ(options.min_inliers, uint32_t{30});
    CHECK_EQ(options.consistent_keyframes, uint32_t{3});
    CHECK(options.odometry_gate);
    CHECK(options.fx == 0.0);
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 7, "metric hint options are ABI 1.7");
    CHECK(options.odometry_max_translation_m == 1.0);
    CHECK(options.odometry_max_translation_per_m == 0.02);
    CHECK(options.pose_reprojection_px == 5.0);
    CHECK(options.odometry_candidates == 1u && options.odometry_search_m == 2.0);
    CHECK(options.max_match_pace == 3.0 && options.match_pace_slack_s == 0.5);
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 18, "TOPOLOC_PAIR_ESTIMATOR_USAC_FAST is ABI 1.18");
    CHECK(options.refine_keyframes == 5u && options.pose_min_inliers == 30u);
    CHECK(options.pair_estimator == TOPOLOC_PAIR_ESTIMATOR_RANSAC &&
          options.pair_iterations == 100u && options.pair_min_cosine == 0.82f);
    CHECK(options.cells_pair_estimator == TOPOLOC_PAIR_ESTIMATOR_MAGSAC &&
          options.cells_pair_iterations == 1000u && options.cells_pair_min_cosine == -1.0f);

    static_assert(static_cast<uint32_t>(topoloc::Gate::Accepted) == TOPOLOC_GATE_ACCEPTED);
    static_assert(static_cast<uint32_t>(topoloc::Gate::NoCandidate) == TOPOLOC_GATE_NO_CANDIDATE);
    static_assert(static_cast<uint32_t>(topoloc::Gate::TooFewInliers) ==
                  TOPOLOC_GATE_TOO_FEW_INLIERS);
    static_assert(static_cast<uint32_t>(topoloc::Gate::Inconsistent) == TOPOLOC_GATE_INCONSISTENT);
    static_assert(static_cast<uint32_t>(topoloc::Gate::NoPose) == TOPOLOC_GATE_NO_POSE);
    static_assert(static_cast<uint32_t>(topoloc::Gate::Odometry) == TOPOLOC_GATE_ODOMETRY);
    static_assert(std::is_same_v<topoloc::LoopCandidate, topoloc_loop_candidate>);

    // A default hint says "nothing matched", with an identity pose and a zero covariance.
    const topoloc::LoopHint hint;
    CHECK(!hint.has_match && !hint.accepted && hint.gate == topoloc::Gate::NoCandidate);
    for (std::size_t i = 0; i < 16; ++i)
        CHECK(hint.matched_T_query[i] == (i % 5 == 0 ? 1.0 : 0.0));
    for (double c : hint.covariance)
        CHECK(c == 0.0);
}

TEST(loop_detector_create_errors)
{
    topoloc::LoopOptions options = test_options();
    CHECK_THROWS_STATUS(topoloc::LoopDetector::create("", "loops", kLoopDim, options),
                        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_THROWS_STATUS(topoloc::LoopDetector::create("test", "loops", 0, options),
                        TOPOLOC_ERR_INVALID_ARGUMENT);
    options.candidates = 0;
    const std::string message =
        CHECK_THROWS_STATUS(topoloc::LoopDetector::create("test", "loops", kLoopDim, options),
                            TOPOLOC_ERR_INVALID_OPTION);
    CHECK(!message.empty());
    options = test_options();
    options.struct_size = 3;
    CHECK_THROWS_STATUS(topoloc::LoopDetector::create("test", "loops", kLoopDim, options),
                        TOPOLOC_ERR_STRUCT_SIZE);

    // Defaults are usable as they are.
    const topoloc::LoopDetector detector = topoloc::LoopDetector::create("test", "loops", kLoopDim);
    CHECK(static_cast<bool>(detector));
    CHECK_EQ(detector.size(), std::size_t{0});
}

TEST(loop_detector_moves)
{
    static_assert(!std::is_copy_constructible_v<topoloc::LoopDetector>);
    static_assert(!std::is_copy_assignable_v<topoloc::LoopDetector>);
    static_assert(std::is_nothrow_move_constructible_v<topoloc::LoopDetector>);
    static_assert(std::is_nothrow_move_assignable_v<topoloc::LoopDetector>);
    static_assert(!std::is_convertible_v<topoloc::LoopDetector, bool>,
                  "operator bool must be explicit");
    static_assert(std::is_base_of_v<
                  topoloc::detail::Owner<topoloc_loop_detector, &topoloc_loop_detector_free>,
                  topoloc::LoopDetector>);

    topoloc::LoopDetector a = test_detector();
    const topoloc_loop_detector *raw = a.capi();
    CHECK(raw != nullptr && a.get() == raw);
    (void)a.add(keyframe(0, 0.0, false));

    topoloc::LoopDetector b(std::move(a)); // move construction
    CHECK(!a);
    CHECK(a.capi() == nullptr);
    CHECK(b.capi() == raw);
    CHECK_EQ(b.size(), std::size_t{1});
    // An empty owner throws NULL_ARGUMENT instead of crashing.
    CHECK_THROWS_STATUS(a.size(), TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK_THROWS_STATUS(a.add(keyframe(10, 10.0, true)), TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK_THROWS_STATUS(a.query(loop_descriptor(1), 4), TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK_THROWS_STATUS(a.erase(0), TOPOLOC_ERR_NULL_ARGUMENT);

    // Move assignment over a live detector frees the old one (ASan would see a leak).
    topoloc::LoopDetector c = test_detector();
    c = std::move(b);
    CHECK(!b);
    CHECK(c.capi() == raw);
    // The moved detector keeps its keyframes: the revisit closes the loop.
    const topoloc::LoopHint hint = c.add(keyframe(10, 10.0, true));
    CHECK(hint.accepted && hint.matched_id == 0);
    assign_from(c, c); // self-move-assignment keeps the detector
    CHECK(c.capi() == raw);
    CHECK_EQ(c.size(), std::size_t{2});

    // release() hands the handle to C code, which frees it.
    topoloc_loop_detector *released = c.release();
    CHECK(!c && released == raw);
    std::size_t len = 0;
    CHECK(topoloc_loop_detector_len(released, &len) == TOPOLOC_OK && len == 2);
    topoloc_loop_detector_free(released);
    const topoloc::LoopDetector adopted(nullptr); // null gives an empty owner
    CHECK(!adopted);
}

TEST(loop_closure_flow)
{
    topoloc::LoopDetector detector = test_detector();

    const topoloc::LoopHint first = detector.add(keyframe(0, 0.0, false));
    CHECK_EQ(first.query_id, uint64_t{0});
    CHECK(!first.has_match && !first.accepted);
    CHECK(first.gate == topoloc::Gate::NoCandidate);
    CHECK_EQ(detector.size(), std::size_t{1});

    // Bad keyframes: each throws the right Error and leaves the detector with one keyframe.
    topoloc::LoopKeyframe bad = keyframe(10, 10.0, true);
    bad.descriptor.pop_back();
    const std::string message =
        CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_DIMENSION_MISMATCH);
    CHECK(message.find(std::to_string(kLoopDim)) != std::string::npos); // names the expected D
    try {
        (void)detector.add(bad);
        CHECK(false);
    } catch (const topoloc::Error &e) {
        CHECK(e.status() == TOPOLOC_ERR_DIMENSION_MISMATCH);
        CHECK(std::string(e.what()).find(" [TOPOLOC_ERR_DIMENSION_MISMATCH = 200]: ") !=
              std::string::npos);
    }
    CHECK_EQ(detector.size(), std::size_t{1});

    bad = keyframe(0, 10.0, true); // the id of a keyframe already held
    CHECK(!CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_INVALID_ARGUMENT).empty());
    bad = keyframe(10, std::numeric_limits<double>::quiet_NaN(), true);
    CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_NON_FINITE);
    bad = keyframe(10, 10.0, true);
    bad.descriptor.assign(kLoopDim, 0.f);
    CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_ZERO_DESCRIPTOR);
    // Arrays that disagree are caught by this layer, before any C call reads past them.
    bad = keyframe(10, 10.0, true);
    bad.keypoint_descriptors.pop_back();
    CHECK(CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_INVALID_ARGUMENT)
              .find("keypoint_descriptors") != std::string::npos);
    bad = keyframe(10, 10.0, true);
    bad.keypoints.pop_back();
    CHECK(CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_INVALID_ARGUMENT).find("keypoints") !=
          std::string::npos);
    bad = keyframe(10, 10.0, true);
    bad.camera_points.assign(3 * kLoopPoints - 1, 1.f);
    CHECK(CHECK_THROWS_STATUS(detector.add(bad), TOPOLOC_ERR_INVALID_ARGUMENT)
              .find("camera_points") != std::string::npos);
    bad = keyframe(10, 10.0, true);
    bad.world_T_body = pose_at(0.0, 0.0); // poses on some keyframes only
    bool refused = false;
    try {
        (void)detector.add(bad);
    } catch (const topoloc::Error &e) {
        refused = !e.message().empty();
    }
    CHECK(refused);
    CHECK_EQ(detector.size(), std::size_t{1});

    // The revisit from another pose: every keypoint matches, the hint names keyframe 0.
    const topoloc::LoopHint hint = detector.add(keyframe(10, 10.0, true));
    CHECK_EQ(hint.query_id, uint64_t{10});
    CHECK(hint.has_match && hint.accepted);
    CHECK(hint.gate == topoloc::Gate::Accepted);
    CHECK_EQ(hint.matched_id, uint64_t{0});
    CHECK_EQ(hint.place, first.query_place);
    CHECK(hint.inliers >= 30);
    CHECK(hint.confidence > 0.99f);
    CHECK(!hint.has_pose && !hint.scale_known); // no intrinsics
    CHECK_EQ(detector.size(), std::size_t{2});

    // Relocalization: both keyframes, most similar first; at most `max`.
    const std::vector<topoloc::LoopCandidate> found = detector.query(loop_descriptor(1), 4);
    CHECK_EQ(found.size(), std::size_t{2});
    if (!found.empty())
        CHECK(found[0].similarity > 0.99f);
    for (std::size_t i = 1; i < found.size(); ++i)
        CHECK(found[i - 1].similarity >= found[i].similarity);
    CHECK_EQ(detector.query(loop_descriptor(1), 1).size(), std::size_t{1});
    CHECK(detector.query(loop_descriptor(1), 0).empty());
    CHECK_EQ(detector.query(loop_descriptor(1), std::numeric_limits<std::size_t>::max()).size(),
             std::size_t{2});
    CHECK_THROWS_STATUS(detector.query(std::vector<float>(kLoopDim + 1, 1.f), 4),
                        TOPOLOC_ERR_DIMENSION_MISMATCH);

    // Save, erase, and a second session from the saved map.
    TempDir dir;
    const std::string path = (dir.path / "loops.topoloc").string();
    detector.save(path);
    CHECK_THROWS_STATUS(detector.save((dir.path / "no-such-dir" / "x.topoloc").string()),
                        TOPOLOC_ERR_IO);
    CHECK_THROWS_STATUS(detector.erase(77), TOPOLOC_ERR_INVALID_ARGUMENT);
    detector.erase(10);
    CHECK_EQ(detector.size(), std::size_t{1});

    const topoloc::Map saved = topoloc::Map::load(path);
    CHECK_EQ(saved.view_count(), std::size_t{2});
    CHECK_EQ(saved.dim(), kLoopDim);
    CHECK(saved.descriptor_kind() == "test");
    CHECK(saved.descriptor_model() == "loops");
    CHECK(saved.view_info(1).keyframe_id == std::optional<uint64_t>(10));
    topoloc::LoopDetector again = topoloc::LoopDetector::from_map(saved);
    CHECK_EQ(again.size(), std::size_t{2});
    // A new image of the spot (its keypoints a quarter pixel off the saved ones: the very same
    // keypoints would be the saved keyframe's own image, Gate::SelfMatch).
    topoloc::LoopKeyframe new_image = keyframe(20, 20.0, true);
    for (float &v : new_image.keypoints)
        v += 0.25f;
    const topoloc::LoopHint later = again.add(new_image);
    CHECK_EQ(later.query_id, uint64_t{20});
    // Verified against the saved keypoints (the first keyframe of a streak at the defaults).
    CHECK(later.has_match && later.inliers >= 30);
    CHECK(later.gate == topoloc::Gate::Inconsistent);
    CHECK_EQ(again.size(), std::size_t{3});
    CHECK_THROWS_STATUS(again.add(keyframe(5, 30.0, true)), TOPOLOC_ERR_INVALID_ARGUMENT);

    // An empty detector has nothing to save.
    CHECK_THROWS_STATUS(test_detector().save(path), TOPOLOC_ERR_EMPTY_MAP);
}

TEST(loop_detector_from_map_errors)
{
    CHECK_THROWS_STATUS(topoloc::LoopDetector::from_map(topoloc::Map()), TOPOLOC_ERR_NULL_ARGUMENT);
    // A map whose views have no keyframe ids cannot be a session.
    topoloc::MapBuilder builder("test", "loops", kLoopDim);
    const uint32_t place = builder.add_place();
    builder.add_view(place, loop_descriptor(1));
    CHECK_THROWS_STATUS(topoloc::LoopDetector::from_map(builder.build()),
                        TOPOLOC_ERR_INVALID_OPTION);
    // A map with keyframe ids (the chain fixture) is one.
    const topoloc::LoopDetector detector = topoloc::LoopDetector::from_map(chain_map());
    CHECK_EQ(detector.size(), std::size_t{kPlaces * kViews});
    // A new run's ids go on past the map's largest.
    CHECK_EQ(detector.next_id(), std::uint64_t{(kPlaces - 1) * 100 + kViews});
}

// The test options with the pinhole intrinsics of the two-view scene.
topoloc::LoopOptions options_with_intrinsics()
{
    topoloc::LoopOptions options = test_options();
    options.fx = 300.0;
    options.fy = 300.0;
    options.cx = 160.0;
    options.cy = 120.0;
    return options;
}

TEST(metric_hint_with_intrinsics)
{
    const topoloc::LoopOptions options = options_with_intrinsics();
    topoloc::LoopDetector detector =
        topoloc::LoopDetector::create("test", "loops", kLoopDim, options);
    topoloc::LoopKeyframe first = keyframe(0, 0.0, false);
    first.camera_points = two_views().scene; // the matched keyframe knows its scene: metric
    (void)detector.add(first);
    const topoloc::LoopHint hint = detector.add(keyframe(10, 10.0, true));
    CHECK(hint.accepted && hint.gate == topoloc::Gate::Accepted && hint.matched_id == 0);
    CHECK(hint.has_pose && hint.scale_known && hint.translation == topoloc::Translation::Metric);
    if (hint.has_pose) {
        // The second camera sits 0.3 m right and 0.1 m ahead of the first, turned 3 degrees.
        const topoloc::Pose &T = hint.matched_T_query;
        CHECK(std::abs(T[3] - 0.3) < 0.05 && std::abs(T[7]) < 0.05 && std::abs(T[11] - 0.1) < 0.05);
        CHECK(std::abs(T[0] - 0.99862953475) < 0.005 && std::abs(T[2] - 0.05233595624) < 0.02);
        CHECK(T[12] == 0.0 && T[13] == 0.0 && T[14] == 0.0 && T[15] == 1.0);
        for (std::size_t i = 0; i < 6; ++i) {
            CHECK(hint.covariance[i * 6 + i] > 0.0); // positive variances
            for (std::size_t j = 0; j < i; ++j) {    // symmetric (up to rounding)
                const double a = hint.covariance[i * 6 + j], b = hint.covariance[j * 6 + i];
                CHECK(std::abs(a - b) <= 1e-9 * (std::abs(a) + std::abs(b)) + 1e-15);
            }
        }
    }
}

TEST(a_hint_says_what_its_translation_holds_and_its_own_image_is_refused)
{
    // Without scene points: a unit direction.
    const topoloc::LoopOptions options = options_with_intrinsics();
    topoloc::LoopDetector first = topoloc::LoopDetector::create("test", "loops", kLoopDim, options);
    (void)first.add(keyframe(0, 0.0, false));
    const topoloc::LoopHint direction = first.add(keyframe(10, 10.0, true));
    CHECK(direction.accepted && direction.translation == topoloc::Translation::Direction);
    const topoloc::Pose &T = direction.matched_T_query;
    CHECK(std::abs(std::sqrt(T[3] * T[3] + T[7] * T[7] + T[11] * T[11]) - 1.0) < 1e-9);

    // A map of this run: its keyframes again, with the same keypoints, are their own images.
    TempDir dir;
    const std::string path = (dir.path / "own-run.topoloc").string();
    first.save(path);
    topoloc::LoopDetector live = topoloc::LoopDetector::from_map(topoloc::Map::load(path), options);
    const topoloc::LoopHint own = live.add(keyframe(11, 0.0, false));
    CHECK(own.has_match && !own.accepted && own.gate == topoloc::Gate::SelfMatch);
    CHECK_EQ(own.matched_id, uint64_t{0});
}

TEST(loop_add_of_a_c_record)
{
    // The zero-copy overload: the host's own buffers in a C keyframe record.
    topoloc::LoopDetector detector = test_detector();
    const std::vector<float> d = loop_descriptor(1);
    topoloc_loop_keyframe raw;
    CHECK(topoloc_loop_keyframe_default(&raw) == TOPOLOC_OK);
    raw.id = 0;
    raw.descriptor = d.data();
    raw.descriptor_len = d.size();
    raw.keypoint_count = kLoopPoints;
    raw.keypoints = two_views().first.data();
    raw.keypoint_descriptors = two_views().descriptors.data();
    CHECK(detector.add(raw).gate == topoloc::Gate::NoCandidate);
    raw.id = 10;
    raw.timestamp = 10.0;
    raw.keypoints = two_views().second.data();
    raw.struct_size = 3;
    CHECK_THROWS_STATUS(detector.add(raw), TOPOLOC_ERR_STRUCT_SIZE);
    raw.struct_size = sizeof raw;
    raw.keypoint_descriptors = nullptr;
    CHECK(CHECK_THROWS_STATUS(detector.add(raw), TOPOLOC_ERR_NULL_ARGUMENT)
              .find("keyframe.keypoint_descriptors") != std::string::npos);
    raw.keypoint_descriptors = two_views().descriptors.data();
    CHECK_EQ(detector.size(), std::size_t{1});
    const topoloc::LoopHint hint = detector.add(raw);
    CHECK(hint.accepted && hint.matched_id == 0);
}

// A describer of an image map (ABI 1.12) describes each map image as its view was described,
// feeds a detector made for the map's descriptors, moves, and throws typed errors.
TEST(describer_feeds_a_loop_detector)
{
    const topoloc::Map &map = image_map();
    topoloc::Describer describer(map);
    CHECK(static_cast<bool>(describer));
    CHECK_EQ(describer.dim(), std::size_t{map.dim()});
    std::vector<float> out;
    for (uint32_t p = 0; p < kImgPlaces; ++p) {
        describer.describe(gray(places_pixels()[p]), out);
        const std::vector<float> view = map.view_descriptor(p);
        CHECK_EQ(out.size(), view.size());
        double dot = 0.0;
        for (std::size_t k = 0; k < out.size() && k < view.size(); ++k)
            dot += double(out[k]) * view[k];
        CHECK(dot > 0.9999);
    }

    topoloc::LoopDetector detector = topoloc::LoopDetector::for_descriptors_of(map);
    topoloc::LoopKeyframe keyframe;
    keyframe.id = 1;
    keyframe.descriptor = describer.describe(gray(places_pixels()[0]));
    const topoloc::LoopHint hint = detector.add(keyframe);
    CHECK(!hint.has_match && !hint.accepted);
    CHECK_EQ(detector.size(), std::size_t{1});

    // A failed describe leaves the output untouched.
    const std::vector<float> before = out;
    CHECK_THROWS_STATUS(describer.describe(topoloc::Image{}, out), TOPOLOC_ERR_INVALID_IMAGE);
    CHECK(out == before);
    std::vector<uint8_t> flat(kImgW * kImgH, 128);
    CHECK_THROWS_STATUS(describer.describe(gray(flat), out), TOPOLOC_ERR_UNINFORMATIVE_IMAGE);
    CHECK(out == before);

    topoloc::Describer moved(std::move(describer));
    CHECK(!describer && static_cast<bool>(moved));
    CHECK_EQ(moved.describe(gray(places_pixels()[1])).size(), std::size_t{map.dim()});

    // Maps built from descriptors store no describer; options it cannot honour.
    topoloc::MapBuilder builder("ext", "m", 4);
    (void)builder.add_place();
    const std::array<float, 4> d{1, 0, 0, 0};
    (void)builder.add_view(0, d.data(), d.size());
    const topoloc::Map plain = builder.build();
    CHECK_THROWS_STATUS(topoloc::Describer{plain}, TOPOLOC_ERR_NO_DESCRIBER);
    topoloc::DescriberOptions options = topoloc::default_describer_options();
    options.backend = TOPOLOC_BACKEND_ONNX;
    CHECK_THROWS_STATUS((topoloc::Describer{map, options}), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
}

} // namespace

// With a streak of 3 (the default), keyframes 10 and 11 revisit keyframe 0 but wait as
// inconsistent; keyframe 12 completes the streak and `confirmed()` names both (ABI 1.10).
TEST(a_completed_streak_confirms_its_first_keyframes)
{
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 10, "confirmed hints are ABI 1.10");
    topoloc::LoopOptions options = test_options();
    options.consistent_keyframes = 3;
    auto detector = topoloc::LoopDetector::create("test", "loops", kLoopDim, options);
    (void)detector.add(keyframe(0, 0.0, false));
    CHECK(detector.confirmed().empty());
    for (uint64_t id : {10, 11}) {
        const topoloc::LoopHint hint = detector.add(keyframe(id, double(id), true));
        CHECK(hint.gate == topoloc::Gate::Inconsistent && !hint.accepted);
        CHECK(detector.confirmed().empty());
    }
    const topoloc::LoopHint hint = detector.add(keyframe(12, 12.0, true));
    CHECK(hint.accepted && hint.query_id == 12);
    const std::vector<topoloc::LoopHint> confirmed = detector.confirmed();
    CHECK_EQ(confirmed.size(), std::size_t{2});
    if (confirmed.size() == 2) {
        CHECK(confirmed[0].query_id == 10 && confirmed[1].query_id == 11);
        for (const auto &c : confirmed)
            CHECK(c.accepted && c.gate == topoloc::Gate::Accepted && c.matched_id == 0 &&
                  c.inliers >= 30);
    }
    (void)detector.add(keyframe(13, 13.0, true));
    CHECK(detector.confirmed().empty());
    CHECK_THROWS_STATUS(topoloc::LoopDetector().confirmed(), TOPOLOC_ERR_NULL_ARGUMENT);
}

// A new session (ABI 1.15): keyframe 3 is inside the exclusion window of keyframe 0 (5 ids);
// after `begin_session` (a host's new map, its clock restarted) keyframe 4, earlier in time,
// finds the keyframes of the session just ended.
TEST(a_new_session_finds_the_keyframes_just_lost)
{
    topoloc::LoopDetector detector = test_detector();
    (void)detector.add(keyframe(0, 100.0, false));
    CHECK(detector.add(keyframe(3, 100.5, true)).gate == topoloc::Gate::NoCandidate);
    detector.begin_session();
    const topoloc::LoopHint hint = detector.add(keyframe(4, 0.0, true));
    CHECK(hint.accepted && (hint.matched_id == 0 || hint.matched_id == 3));
    CHECK_THROWS_STATUS(detector.add(keyframe(5, -1.0, true)), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_EQ(detector.size(), std::size_t{3});
    CHECK_THROWS_STATUS(topoloc::LoopDetector().begin_session(), TOPOLOC_ERR_NULL_ARGUMENT);
}

int main() { return run_all_tests(); }
