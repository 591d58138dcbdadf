// Tests of the C++ RAII layer (include/topoloc.hpp): ownership and moves, exceptions carrying
// the C status and message, the full builder -> save -> load -> localize flow, a localizer that
// outlives its Map owner, the ABI check, and images: maps built from images and image files
// with progress callbacks (cancel, exceptions thrown by the callback), image frames, the
// exception subclasses of the image statuses. (cv::Mat conveniences: test_opencv.cpp.) Built and
// run by tests/cpp/run.sh, normally and under ASan+UBSan (which is what turns a double free or a
// leak into a failure).

#include "topoloc.hpp"
#include "topoloc.hpp" // deliberately twice: the include guard must make this harmless

#include "harness.hpp"

#include <typeindex>
#include <typeinfo>

namespace {

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

TEST(abi_and_version)
{
    CHECK(topoloc::abi_matches());
    CHECK_EQ(topoloc::abi_version(), uint32_t{TOPOLOC_ABI_VERSION});
    CHECK_EQ(topoloc::header_abi_version, uint32_t{TOPOLOC_ABI_VERSION});
    CHECK(std::string(topoloc::version()) == TOPOLOC_VERSION_STRING);
    CHECK(std::string(topoloc::status_string(TOPOLOC_ERR_IO)) == "I/O error");
}

// An owner class of the layer: move-only (copies deleted, moves noexcept), an explicit `operator
// bool`, and derived from the one owner template over its C handle, not a hand-written owner.
template <typename T, typename Handle, void (*Free)(Handle *)>
constexpr bool is_owner_v =
    !std::is_copy_constructible_v<T> && !std::is_copy_assignable_v<T> &&
    std::is_nothrow_move_constructible_v<T> && std::is_nothrow_move_assignable_v<T> &&
    !std::is_convertible_v<T, bool> && std::is_base_of_v<topoloc::detail::Owner<Handle, Free>, T>;

TEST(owners_are_move_only)
{
    static_assert(is_owner_v<topoloc::Map, topoloc_map, &topoloc_map_free>);
    static_assert(is_owner_v<topoloc::MapBuilder, topoloc_map_builder, &topoloc_map_builder_free>);
    static_assert(is_owner_v<topoloc::Localizer, topoloc_localizer, &topoloc_localizer_free>);
    static_assert(is_owner_v<topoloc::Graph, topoloc_graph, &topoloc_graph_free>);
    static_assert(is_owner_v<topoloc::Describer, topoloc_describer, &topoloc_describer_free>);
    static_assert(is_owner_v<topoloc::KeyframeDescriber, topoloc_keyframe_describer,
                             &topoloc_keyframe_describer_free>);
    static_assert(
        is_owner_v<topoloc::LoopDetector, topoloc_loop_detector, &topoloc_loop_detector_free>);
    // get() is capi().
    topoloc::Map map = chain_map();
    CHECK(map.get() == map.capi() && map.get() != nullptr);
    const topoloc::Map &const_map = map;
    CHECK(const_map.get() == const_map.capi());
}

TEST(map_moves)
{
    topoloc::Map a = chain_map();
    CHECK(static_cast<bool>(a));
    const topoloc_map *raw = a.capi();

    topoloc::Map b(std::move(a)); // move construction
    CHECK(!a);
    CHECK(a.capi() == nullptr);
    CHECK(b.capi() == raw);
    CHECK_EQ(b.place_count(), std::size_t{kPlaces});

    topoloc::Map c = chain_map(); // move assignment over a live map frees the old one (ASan)
    c = std::move(b);
    CHECK(!b);
    CHECK(c.capi() == raw);

    assign_from(c, c); // self-move-assignment keeps the map
    CHECK(c.capi() == raw);

    // An empty owner throws NULL_ARGUMENT instead of crashing.
    CHECK_THROWS_STATUS(a.place_count(), TOPOLOC_ERR_NULL_ARGUMENT);
    topoloc::Map empty;
    CHECK(!empty);

    // release() hands the handle to C code, which frees it.
    topoloc_map *released = c.release();
    CHECK(!c);
    CHECK(released == raw);
    topoloc_map_free(released);
}

TEST(builder_moves)
{
    topoloc::MapBuilder a = chain_builder();
    const topoloc_map_builder *raw = a.capi();
    topoloc::MapBuilder b = std::move(a);
    CHECK(!a);
    CHECK(a.capi() == nullptr);
    CHECK(b.capi() == raw);
    CHECK_THROWS_STATUS(a.add_place(), TOPOLOC_ERR_NULL_ARGUMENT);

    topoloc::MapBuilder c("other", "", kDim);
    c = std::move(b);
    CHECK(!b);
    CHECK(c.capi() == raw);
    CHECK_EQ(c.build().place_count(), std::size_t{kPlaces});
}

TEST(localizer_moves)
{
    const topoloc::Map map = chain_map();
    topoloc::Localizer a(map);
    const topoloc_localizer *raw = a.capi();
    (void)a.process(observe(0, 0), 0.0);

    topoloc::Localizer b(std::move(a));
    CHECK(!a);
    CHECK(a.capi() == nullptr);
    CHECK_EQ(a.candidate_capacity(), std::size_t{0});
    CHECK(b.capi() == raw);
    CHECK_EQ(b.candidate_capacity(), std::size_t{5});
    // The moved localizer keeps its state: frame 1 follows frame 0.
    CHECK_EQ(b.process(observe(0, 1), 0.1).frame_index, uint64_t{1});
    CHECK_THROWS_STATUS(a.process(observe(0, 1), 0.1), TOPOLOC_ERR_NULL_ARGUMENT);

    topoloc::Localizer c(map);
    c = std::move(b);
    CHECK(!b);
    CHECK(c.capi() == raw);
    CHECK_EQ(c.process(observe(0, 2), 0.2).frame_index, uint64_t{2});
    assign_from(c, c);
    CHECK(c.capi() == raw);
}

TEST(graph_moves)
{
    // A free corridor 40 x 8 voxels of 0.1 m (walls around it), 3 voxels high.
    const std::array<std::size_t, 3> dims{40, 8, 3};
    std::vector<uint8_t> cells(dims[0] * dims[1] * dims[2], 0);
    for (std::size_t z = 0; z < dims[2]; ++z)
        for (std::size_t y = 0; y < dims[1]; ++y)
            for (std::size_t x = 0; x < dims[0]; ++x)
                if (x == 0 || y == 0 || x + 1 == dims[0] || y + 1 == dims[1])
                    cells[x + dims[0] * (y + dims[1] * z)] = 1;
    topoloc::Graph a = topoloc::Graph::from_occupancy(dims, 0.1, {0.0, 0.0, 0.0}, cells);
    CHECK(static_cast<bool>(a));
    CHECK(a.place_count() >= 2);
    const topoloc_graph *raw = a.capi();
    topoloc::Graph b(std::move(a));
    CHECK(!a && b.capi() == raw);
    CHECK_THROWS_STATUS(a.place_count(), TOPOLOC_ERR_NULL_ARGUMENT);
    topoloc::Graph c = topoloc::Graph::from_occupancy(dims, 0.1, {0.0, 0.0, 0.0}, cells);
    c = std::move(b); // frees c's first graph (ASan would see a leak or a double free)
    CHECK(!b && c.capi() == raw);
    CHECK_EQ(c.edges().size(), c.edge_count());
    topoloc_graph *released = c.release();
    CHECK(!c && released == raw);
    topoloc_graph_free(released);
}

TEST(dimension_mismatch_throws)
{
    const topoloc::Map map = chain_map();
    topoloc::Localizer localizer(map);
    const topoloc::Result first = localizer.process(observe(1, 0), 0.0);

    const std::vector<float> short_descriptor(kDim - 1, 0.5f);
    const std::string message = CHECK_THROWS_STATUS(localizer.process(short_descriptor, 0.1),
                                                    TOPOLOC_ERR_DIMENSION_MISMATCH);
    CHECK(!message.empty());
    CHECK(message.find(std::to_string(kDim)) != std::string::npos); // names the expected D

    // what() = status description + message.
    try {
        (void)localizer.process(short_descriptor, 0.1);
    } catch (const topoloc::Error &e) {
        const std::string what = e.what();
        CHECK(what.find("descriptor dimension mismatch") == 0);
        CHECK(what.find(" [TOPOLOC_ERR_DIMENSION_MISMATCH = 200]: ") != std::string::npos);
        CHECK(what.find(e.message()) != std::string::npos);
    }

    // A failed call leaves the localizer and its last result unchanged.
    CHECK_EQ(localizer.last_result().frame_index, first.frame_index);
    CHECK_EQ(localizer.process(observe(1, 1), 0.1).frame_index, uint64_t{1});

    // The builder reports the same status.
    topoloc::MapBuilder builder("test", "", kDim);
    const uint32_t place = builder.add_place();
    CHECK_THROWS_STATUS(builder.add_view(place, std::vector<float>(kDim + 1, 1.f)),
                        TOPOLOC_ERR_DIMENSION_MISMATCH);
}

TEST(other_statuses_throw)
{
    const topoloc::Map map = chain_map();
    topoloc::Localizer localizer(map);
    (void)localizer.process(observe(0, 0), 1.0);
    CHECK_THROWS_STATUS(localizer.process(observe(0, 1), 0.5), TOPOLOC_ERR_TIMESTAMP);
    CHECK_THROWS_STATUS(localizer.process(std::vector<float>(kDim, 0.f), 2.0),
                        TOPOLOC_ERR_ZERO_DESCRIPTOR);
    std::vector<float> nan_descriptor = observe(0, 1);
    nan_descriptor[3] = std::nanf("");
    CHECK_THROWS_STATUS(localizer.process(nan_descriptor, 2.0), TOPOLOC_ERR_NON_FINITE);
    topoloc::Pose not_rigid = pose_at(0, 0);
    not_rigid[0] = 2.0; // scales x
    CHECK_THROWS_STATUS(localizer.process(observe(0, 1), 2.0, not_rigid),
                        TOPOLOC_ERR_INVALID_ARGUMENT);

    CHECK_THROWS_STATUS(map.neighbours(kPlaces), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_THROWS_STATUS(map.place_position(kPlaces + 7), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_THROWS_STATUS(map.view_info(kPlaces * kViews), TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_THROWS_STATUS(map.view_descriptor(kPlaces * kViews), TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_THROWS_STATUS(map.edge(map.edge_count()), TOPOLOC_ERR_INVALID_ARGUMENT);

    topoloc::LocalizerOptions bad = topoloc::default_localizer_options();
    bad.top_k = 0;
    CHECK_THROWS_STATUS((void)topoloc::Localizer(map, bad), TOPOLOC_ERR_INVALID_OPTION);
    topoloc::LocalizerOptions unset{}; // struct_size 0: not filled by the _default function
    CHECK_THROWS_STATUS((void)topoloc::Localizer(map, unset), TOPOLOC_ERR_STRUCT_SIZE);

    topoloc::MapBuilder builder("test", "", kDim);
    builder.add_place();
    CHECK_THROWS_STATUS(builder.build(), TOPOLOC_ERR_INVALID_MAP); // a place without views
    CHECK_THROWS_STATUS((void)topoloc::MapBuilder("", "", kDim), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_THROWS_STATUS(topoloc::MapBuilder("test", "", kDim).build(), TOPOLOC_ERR_EMPTY_MAP);

    // check() itself.
    topoloc::check(TOPOLOC_OK);
    CHECK_THROWS_STATUS(topoloc::check(TOPOLOC_ERR_PANIC), TOPOLOC_ERR_PANIC);
}

TEST(missing_file_throws_io)
{
    TempDir dir;
    const std::string path = (dir.path / "no-such-map.topoloc").string();
    const std::string message = CHECK_THROWS_STATUS(topoloc::Map::load(path), TOPOLOC_ERR_IO);
    CHECK(message.find(path) != std::string::npos);

    // A message longer than any first guess of a buffer size is read whole.
    const std::string long_path = (dir.path / (std::string(200, 'x') + ".topoloc")).string();
    const std::string long_message =
        CHECK_THROWS_STATUS(topoloc::Map::load(long_path), TOPOLOC_ERR_IO);
    CHECK(long_message.size() > 200);
    CHECK(long_message.find(long_path) != std::string::npos);
    CHECK(topoloc::last_error_message() == long_message); // reading does not consume it

    // Saving into a directory that does not exist fails with IO too.
    const topoloc::Map map = chain_map();
    CHECK_THROWS_STATUS(map.save((dir.path / "missing" / "m.topoloc").string()), TOPOLOC_ERR_IO);
}

TEST(full_flow_build_save_load_localize)
{
    TempDir dir;
    const std::string path = (dir.path / "chain.topoloc").string();
    {
        const topoloc::MapBuilder builder = chain_builder();
        builder.build().save(path);
    }

    topoloc::LoadOptions load_options = topoloc::default_load_options();
    load_options.expected_descriptor_kind = "test";
    load_options.expected_descriptor_dim = kDim;
    const topoloc::Map map = topoloc::Map::load(path, load_options);

    CHECK_EQ(map.place_count(), std::size_t{kPlaces});
    CHECK_EQ(map.view_count(), std::size_t{kPlaces * kViews});
    CHECK_EQ(map.edge_count(), std::size_t{kPlaces - 1});
    CHECK_EQ(map.dim(), kDim);
    CHECK(map.descriptor_kind() == "test");
    CHECK(map.descriptor_model() == "chain-v1");

    CHECK(map.neighbours(0) == std::vector<uint32_t>{1});
    CHECK((map.neighbours(2) == std::vector<uint32_t>{1, 3}));
    CHECK_EQ(map.place_views(3).size(), std::size_t{kViews});
    const auto position = map.place_position(3);
    CHECK(position.has_value());
    if (position)
        CHECK_EQ((*position)[0], 6.0);

    const std::vector<topoloc::Edge> edges = map.edges();
    CHECK_EQ(edges.size(), std::size_t{kPlaces - 1});
    for (std::size_t i = 0; i < edges.size(); ++i) {
        CHECK_EQ(edges[i].a, uint32_t(i));
        CHECK_EQ(edges[i].b, uint32_t(i + 1));
        CHECK_EQ(edges[i].weight, 1.0f);
    }

    for (const uint32_t view : map.place_views(2)) {
        const topoloc::ViewInfo info = map.view_info(view);
        CHECK_EQ(info.place, uint32_t{2});
        CHECK(info.keyframe_id.has_value());
        CHECK(info.world_T_camera.has_value());
        if (!info.keyframe_id || !info.world_T_camera)
            continue;
        const uint32_t v = static_cast<uint32_t>(*info.keyframe_id % 100);
        CHECK_EQ(*info.keyframe_id / 100, uint64_t{2});
        CHECK(std::abs((*info.world_T_camera)[3] - 4.0) < 1e-9);
        CHECK_EQ((*info.world_T_camera)[15], 1.0);
        const std::string image = map.view_image(view);
        CHECK(image == (v % 2 == 0 ? "images/place2_view" + std::to_string(v) + ".png" : ""));
        const std::vector<float> d = map.view_descriptor(view);
        CHECK_EQ(d.size(), std::size_t{kDim});
        CHECK(std::abs(dot(d, d) - 1.f) < 1e-4f);
        CHECK(std::abs(dot(d, view_descriptor_seed(2, v)) - 1.f) < 1e-4f);
    }

    // The same bytes through from_memory give the same map.
    std::ifstream file(path, std::ios::binary);
    const std::vector<uint8_t> bytes{std::istreambuf_iterator<char>(file),
                                     std::istreambuf_iterator<char>()};
    const topoloc::Map copy = topoloc::Map::from_memory(bytes);
    CHECK_EQ(copy.view_count(), map.view_count());
    CHECK(copy.view_descriptor(7) == map.view_descriptor(7));

    // Expecting another descriptor refuses the map.
    topoloc::LoadOptions other = topoloc::default_load_options();
    other.expected_descriptor_model = "chain-v2";
    CHECK_THROWS_STATUS(topoloc::Map::load(path, other), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);

    // Localize a walk along the chain.
    topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    options.top_k = 3;
    options.expected_descriptor_kind = "test";
    topoloc::Localizer localizer(map, options);
    CHECK_EQ(localizer.candidate_capacity(), std::size_t{3});
    CHECK_EQ(walk(localizer), int(kPlaces * 3));
    CHECK_EQ(localizer.last_result().candidates.size(), std::size_t{3});

    // reset(): history forgotten, so an earlier timestamp is accepted and frames count from 0.
    localizer.reset();
    CHECK_EQ(localizer.last_result().candidates.size(), std::size_t{0});
    CHECK_EQ(walk(localizer, -5.0), int(kPlaces * 3));

    // Single-frame mode and a top_k larger than the map (capped at the number of places).
    options.mode = TOPOLOC_MODE_SINGLE_FRAME;
    options.top_k = 100;
    topoloc::Localizer single(map, options);
    CHECK_EQ(single.candidate_capacity(), std::size_t{kPlaces});
    const topoloc::Result &r = single.process(observe(4, 9), 0.0);
    CHECK_EQ(r.place, uint32_t{4});
    CHECK_EQ(r.candidates.size(), std::size_t{kPlaces});

    // The learned mode (ABI 1.16): a model file that does not exist is named before ONNX
    // Runtime is loaded (python/train/smoke.py runs the whole learned path).
    static_assert(TOPOLOC_ABI_VERSION_MINOR >= 16, "the learned mode is ABI 1.16");
    options.mode = TOPOLOC_MODE_GRNN;
    const std::string missing_model = "/nonexistent/grnn.onnx";
    options.grnn_model_path = missing_model.c_str();
    const std::string grnn_message =
        CHECK_THROWS_STATUS(topoloc::Localizer(map, options), TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK(grnn_message.find(missing_model) != std::string::npos);
}

TEST(localizer_outlives_map_owner)
{
    TempDir dir;
    const std::string path = (dir.path / "chain.topoloc").string();
    chain_map().save(path);

    std::optional<topoloc::Localizer> localizer;
    {
        topoloc::Map map = topoloc::Map::load(path);
        localizer.emplace(map);
    } // the Map owner is destroyed here; the localizer holds its own reference
    CHECK_EQ(walk(*localizer), int(kPlaces * 3));
    localizer.reset(); // frees the localizer and with it the last reference to the map
    CHECK(!localizer.has_value());
}

TEST(log_handler_receives_records_up_to_its_level)
{
    TempDir dir;
    const std::string path = (dir.path / "logged.topoloc").string();
    std::mutex mutex;
    std::vector<std::tuple<topoloc::LogLevel, std::string, std::string>> records;
    auto collect = [&](topoloc::LogLevel level, std::string_view target, std::string_view message) {
        std::lock_guard<std::mutex> lock(mutex);
        records.emplace_back(level, std::string(target), std::string(message));
        throw std::runtime_error("a handler's exception is dropped, not propagated into topoloc");
    };
    topoloc::set_log_handler(collect, topoloc::LogLevel::Info);
    chain_map().save(path);
    (void)topoloc::Map::load(path);
    topoloc::set_log_handler(collect, topoloc::LogLevel::Warn); // info records stop here
    (void)topoloc::Map::load(path);
    topoloc::set_log_handler(nullptr); // off
    (void)topoloc::Map::load(path);
    CHECK_EQ(records.size(), std::size_t{2});
    if (records.size() == 2) {
        CHECK(std::get<0>(records[0]) == topoloc::LogLevel::Info);
        CHECK(std::get<1>(records[0]) == "topoloc::map::file");
        CHECK(std::get<2>(records[0]).find("saved " + path) == 0);
        CHECK(std::get<2>(records[1]).find("loaded " + path) == 0);
    }
}

TEST(map_from_keyframes)
{
    // A robot driving along x, one keyframe every 0.5 m; places every 2 m.
    std::vector<topoloc::Keyframe> keyframes;
    for (uint32_t i = 0; i < 24; ++i) {
        topoloc::Keyframe k;
        k.id = 7000 + i;
        k.descriptor = mix(unit_vector(300 + i / 4), unit_vector(900 + i), 0.05f);
        k.world_T_camera = pose_at(0.5 * i, 0.0);
        keyframes.push_back(std::move(k));
    }
    const topoloc::Map map = topoloc::map_from_keyframes("test", "kf-v1", kDim, keyframes);
    CHECK(map.place_count() >= 3);
    CHECK(map.place_count() <= keyframes.size());
    CHECK(map.edge_count() >= map.place_count() - 1);
    CHECK(map.descriptor_model() == "kf-v1");
    for (uint32_t v = 0; v < map.view_count(); ++v) {
        const topoloc::ViewInfo info = map.view_info(v);
        CHECK(info.keyframe_id.has_value() && *info.keyframe_id >= 7000);
        CHECK(info.world_T_camera.has_value());
    }

    keyframes[5].descriptor.pop_back(); // the message names the bad keyframe
    const std::string message =
        CHECK_THROWS_STATUS(topoloc::map_from_keyframes("test", "kf-v1", kDim, keyframes),
                            TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(message.find("keyframe 5") != std::string::npos);
    CHECK_THROWS_STATUS(topoloc::map_from_keyframes("test", "", kDim, {}), TOPOLOC_ERR_EMPTY_MAP);
}

TEST(capi_interop)
{
    // The raw handles work with the C API directly.
    topoloc::Map map = chain_map();
    std::size_t places = 0;
    CHECK_EQ(topoloc_map_place_count(map.capi(), &places), TOPOLOC_OK);
    CHECK_EQ(places, std::size_t{kPlaces});

    // An owner can adopt a handle made by C code.
    topoloc_map *raw = nullptr;
    CHECK_EQ(topoloc_map_builder_build(chain_builder().capi(), &raw), TOPOLOC_OK);
    const topoloc::Map adopted(raw);
    CHECK(adopted.capi() == raw);
    CHECK_EQ(adopted.view_count(), std::size_t{kPlaces * kViews});

    topoloc::Localizer localizer(map);
    topoloc_localizer *released = localizer.release();
    CHECK(!localizer);
    CHECK(topoloc_localizer_reset(released) == TOPOLOC_OK);
    topoloc_localizer_free(released);
}

TEST(threads_share_one_map)
{
    // One immutable map, one localizer per thread (the documented model), and per-thread error
    // messages: each thread's Error describes its own failure.
    const topoloc::Map map = chain_map();
    constexpr int kThreads = 4;
    std::vector<int> correct(kThreads, 0);
    std::vector<int> good_messages(kThreads, 0);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
        threads.emplace_back([&map, &correct, &good_messages, t] {
            try {
                topoloc::Localizer localizer(map);
                for (int round = 0; round < 5; ++round) {
                    const std::string path = "/nonexistent/thread-" + std::to_string(t) + "-" +
                                             std::to_string(round) + ".topoloc";
                    try {
                        (void)topoloc::Map::load(path);
                    } catch (const topoloc::Error &e) {
                        if (e.status() == TOPOLOC_ERR_IO &&
                            e.message().find(path) != std::string::npos)
                            ++good_messages[t];
                    }
                    (void)map.view_descriptor(
                        static_cast<uint32_t>(round)); // concurrent const reads
                    localizer.reset();
                    correct[t] += walk(localizer);
                }
            } catch (const std::exception &e) {
                report_failure(__FILE__, __LINE__, std::string("thread threw: ") + e.what());
            }
        });
    }
    for (std::thread &thread : threads)
        thread.join();
    for (int t = 0; t < kThreads; ++t) {
        CHECK_EQ(correct[t], int(5 * kPlaces * 3));
        CHECK_EQ(good_messages[t], 5);
    }
}

TEST(error_subclasses_for_image_statuses)
{
    const std::tuple<topoloc_status, const char *, std::type_index> cases[] = {
        {TOPOLOC_ERR_INVALID_IMAGE, "invalid", typeid(topoloc::InvalidImageError)},
        {TOPOLOC_ERR_UNINFORMATIVE_IMAGE, "uninf", typeid(topoloc::UninformativeImageError)},
        {TOPOLOC_ERR_BACKEND_UNAVAILABLE, "be", typeid(topoloc::BackendUnavailableError)},
        {TOPOLOC_ERR_MODEL, "model", typeid(topoloc::ModelError)},
        {TOPOLOC_ERR_NO_DESCRIBER, "nodesc", typeid(topoloc::NoDescriberError)},
        {TOPOLOC_ERR_CANCELLED, "cancel", typeid(topoloc::CancelledError)},
    };
    for (const auto &[status, message, type] : cases) {
        try {
            topoloc::throw_error(status, message);
        } catch (const topoloc::Error &e) {
            if (std::type_index(typeid(e)) != type || e.message() != message) {
                report_failure(__FILE__, __LINE__,
                               std::string("wrong exception class or message: ") + e.what());
            }
        }
    }
    // Every subclass is an Error with the status; other statuses stay plain Errors.
    CHECK_THROWS_STATUS(topoloc::throw_error(TOPOLOC_ERR_CANCELLED, "x"), TOPOLOC_ERR_CANCELLED);
    try {
        topoloc::check(TOPOLOC_ERR_IO);
    } catch (const topoloc::CancelledError &) {
        report_failure(__FILE__, __LINE__, "IO became a CancelledError");
    } catch (const topoloc::Error &e) {
        CHECK(e.status() == TOPOLOC_ERR_IO);
    }
    static_assert(std::is_base_of_v<topoloc::Error, topoloc::UninformativeImageError>);
    // A code newer than this header (from a newer library) is still an Error carrying it.
    const auto future = static_cast<topoloc_status>(4242u);
    CHECK(topoloc::status_name(future) == nullptr);
    try {
        topoloc::throw_error(future, "from the future");
    } catch (const topoloc::Error &e) {
        CHECK(e.status() == future);
        CHECK(std::string(e.what()).find("[status = 4242]: from the future") != std::string::npos);
    }
    CHECK(std::string(topoloc::status_name(TOPOLOC_ERR_PANIC)) == "TOPOLOC_ERR_PANIC");
    CHECK(std::string(topoloc::status_string(TOPOLOC_ERR_CANCELLED)) != "unknown status code");
}

TEST(image_view_helper)
{
    const std::vector<uint8_t> px(100 * 3 * 10);
    const topoloc::Image packed = topoloc::image_view(px.data(), 100, 10, TOPOLOC_PIXEL_BGR8);
    CHECK_EQ(packed.stride, std::size_t{300});
    CHECK_EQ(packed.data_len, std::size_t{3000});
    CHECK(packed.format == TOPOLOC_PIXEL_BGR8 && packed.width == 100 && packed.height == 10);
    const topoloc::Image strided = topoloc::image_view(px.data(), 90, 10, TOPOLOC_PIXEL_GRAY8, 300);
    CHECK_EQ(strided.data_len, std::size_t{300 * 9 + 90}); // no padding needed after the last row
    CHECK_EQ(topoloc::image_view(px.data(), 0, 10, TOPOLOC_PIXEL_GRAY8).data_len, std::size_t{0});
    CHECK_EQ(topoloc::pixel_bytes(TOPOLOC_PIXEL_RGBA8), std::size_t{4});
    CHECK_EQ(topoloc::pixel_bytes(TOPOLOC_PIXEL_NONE), std::size_t{0});
    CHECK_THROWS_STATUS(topoloc::image_view(px.data(), 10, 10, 99), TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_THROWS_STATUS(topoloc::image_view(px.data(), 10, 10, TOPOLOC_PIXEL_NONE),
                        TOPOLOC_ERR_INVALID_IMAGE);
    // A size whose byte count overflows is refused here, before any C call.
    CHECK_THROWS_STATUS(topoloc::image_view(px.data(), 10, 3, TOPOLOC_PIXEL_GRAY8,
                                            (std::numeric_limits<std::size_t>::max() >> 1) + 1),
                        TOPOLOC_ERR_INVALID_IMAGE);
    const topoloc::Frame frame;
    CHECK(frame.image.format == TOPOLOC_PIXEL_NONE && frame.image.data == nullptr);
}

// Builds a map of `images` whose progress callback counts its calls and answers `go_on`,
// expecting the build to fail with `status`: the error's message and the callback's calls.
std::pair<std::string, int> failed_counted_build(const std::vector<topoloc::Image> &images,
                                                 bool go_on, topoloc_status status)
{
    int calls = 0;
    const std::string message = CHECK_THROWS_STATUS(
        topoloc::Map::build_from_images(images, vlad_options(kImgPlaces),
                                        [&](topoloc::Stage, std::size_t, std::size_t) {
                                            ++calls;
                                            return go_on;
                                        }),
        status);
    return {message, calls};
}

TEST(image_map_progress_and_cancel)
{
    const std::vector<topoloc::Image> images = place_images();
    std::vector<std::tuple<topoloc::Stage, std::size_t, std::size_t>> seen;
    const std::thread::id caller = std::this_thread::get_id();
    bool other_thread = false;
    const topoloc::Map map = topoloc::Map::build_from_images(
        images, vlad_options(kImgPlaces),
        [&](topoloc::Stage stage, std::size_t done, std::size_t total) {
            seen.emplace_back(stage, done, total);
            other_thread = other_thread || std::this_thread::get_id() != caller;
            return true;
        });
    CHECK(!other_thread);
    CHECK(!seen.empty());
    if (!seen.empty()) {
        CHECK(std::get<0>(seen.front()) == topoloc::Stage::Describing);
        CHECK((seen.back() ==
               std::make_tuple(topoloc::Stage::Fitting, std::size_t{1}, std::size_t{1})));
    }
    CHECK(std::find(seen.begin(), seen.end(),
                    std::make_tuple(topoloc::Stage::Describing, std::size_t{kImgPlaces},
                                    std::size_t{kImgPlaces})) != seen.end());
    CHECK_EQ(map.place_count(), std::size_t{kImgPlaces});
    CHECK_EQ(map.dim(), kImgPlaces - 1);
    CHECK(map.descriptor_kind() == "vlad-orb");
    CHECK(map.view_info(3).keyframe_id == std::optional<uint64_t>(3));

    // Returning false cancels.
    const auto [message, calls] = failed_counted_build(images, false, TOPOLOC_ERR_CANCELLED);
    CHECK(!message.empty());
    CHECK(calls >= 1);
    try {
        (void)topoloc::Map::build_from_images(
            images, vlad_options(kImgPlaces),
            [](topoloc::Stage, std::size_t, std::size_t) { return false; });
        report_failure(__FILE__, __LINE__, "a cancelled build returned a map");
    } catch (const topoloc::CancelledError &) {
        CHECK(true);
    }

    // An exception thrown by the callback is rethrown unchanged after the C call, which it
    // cancels; the callback is not called again after throwing.
    for (const topoloc::Stage throw_at : {topoloc::Stage::Describing, topoloc::Stage::Fitting}) {
        int calls_after = 0;
        bool thrown = false;
        try {
            (void)topoloc::Map::build_from_images(
                images, vlad_options(kImgPlaces),
                [&](topoloc::Stage stage, std::size_t, std::size_t) {
                    if (thrown)
                        ++calls_after;
                    if (stage == throw_at) {
                        thrown = true;
                        throw CallbackFailure();
                    }
                    return true;
                });
            report_failure(__FILE__, __LINE__, "the callback's exception was swallowed");
        } catch (const CallbackFailure &) {
            CHECK(thrown);
        } catch (const std::exception &e) {
            report_failure(__FILE__, __LINE__, std::string("wrong exception: ") + e.what());
        }
        CHECK_EQ(calls_after, 0);
    }
    // Not only std::exceptions.
    bool caught_int = false;
    try {
        (void)topoloc::Map::build_from_images(
            images, vlad_options(kImgPlaces),
            [](topoloc::Stage, std::size_t, std::size_t) -> bool { throw 42; });
    } catch (int value) {
        caught_int = value == 42;
    }
    CHECK(caught_int);

    // Bad input: typed errors, the callback never called.
    std::vector<topoloc::Image> bad = images;
    bad[2].stride = 5;
    const auto [bad_message, bad_calls] =
        failed_counted_build(bad, true, TOPOLOC_ERR_INVALID_IMAGE);
    CHECK(bad_message.find("images[2]") != std::string::npos);
    CHECK_EQ(bad_calls, 0);
    CHECK_THROWS_STATUS(
        topoloc::Map::build_from_images(
            std::vector<topoloc::Image>(images.begin(), images.begin() + 1), vlad_options(2)),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    topoloc::ImageMapOptions unset{};
    CHECK_THROWS_STATUS(topoloc::Map::build_from_images(images, unset), TOPOLOC_ERR_STRUCT_SIZE);
}

TEST(image_localizer)
{
    TempDir dir;
    const std::string path = (dir.path / "images.topoloc").string();
    image_map().save(path);
    const topoloc::Map map = topoloc::Map::load(path); // the describer survives the file

    topoloc::LocalizerOptions options = topoloc::default_localizer_options();
    CHECK(options.image_backend == TOPOLOC_BACKEND_AUTO);
    options.mode = TOPOLOC_MODE_SINGLE_FRAME;
    topoloc::Localizer localizer(map, options);
    int correct = 0;
    for (uint32_t p = 0; p < kImgPlaces; ++p) {
        const std::vector<uint8_t> revisit = revisit_pixels(places_pixels()[p], 100 + p);
        const topoloc::Result &r = localizer.process(gray(revisit), double(p));
        CHECK_EQ(r.frame_index, uint64_t{p});
        if (r.place == p)
            ++correct;
    }
    CHECK(correct >= int(kImgPlaces) - 1);

    // The general Frame: an image, or a descriptor (which wins over an image).
    const std::vector<uint8_t> revisit = revisit_pixels(places_pixels()[5], 7);
    topoloc::Frame frame;
    frame.image = gray(revisit);
    frame.timestamp = 10.0;
    CHECK_EQ(localizer.process(frame).place, uint32_t{5});
    const std::vector<float> view2 = map.view_descriptor(2);
    frame.descriptor = view2.data();
    frame.descriptor_len = view2.size();
    CHECK_EQ(localizer.process(frame).place, uint32_t{2});

    // Filter mode with odometry given as a Pose.
    topoloc::Localizer filter(map);
    const topoloc::Pose still = pose_at(0.0, 0.0);
    CHECK_EQ(filter.process(gray(places_pixels()[3]), 0.0).place, uint32_t{3});
    CHECK_EQ(filter.process(gray(revisit_pixels(places_pixels()[3], 9)), 0.1, still).place,
             uint32_t{3});

    // Bad and uninformative images: typed exceptions, localizer unchanged.
    const uint64_t before = filter.last_result().frame_index;
    const std::vector<uint8_t> constant(kImgW * kImgH, 90);
    CHECK_THROWS_STATUS(filter.process(gray(constant), 5.0), TOPOLOC_ERR_UNINFORMATIVE_IMAGE);
    const uint8_t one = 128;
    CHECK_THROWS_STATUS(filter.process(topoloc::image_view(&one, 1, 1, TOPOLOC_PIXEL_GRAY8), 5.0),
                        TOPOLOC_ERR_UNINFORMATIVE_IMAGE);
    topoloc::Image short_buffer = gray(places_pixels()[0]);
    short_buffer.data_len -= 1;
    const std::string short_message =
        CHECK_THROWS_STATUS(filter.process(short_buffer, 5.0), TOPOLOC_ERR_INVALID_IMAGE);
    CHECK(short_message.find("frame.image") != std::string::npos);
    CHECK_THROWS_STATUS(
        filter.process(topoloc::image_view(&one, 10000, 10000, TOPOLOC_PIXEL_GRAY8), 5.0),
        TOPOLOC_ERR_INVALID_IMAGE);
    bool skipped = false;
    try {
        (void)filter.process(gray(constant), 6.0);
    } catch (const topoloc::UninformativeImageError &) {
        skipped = true; // what a stream does: skip the frame
    }
    CHECK(skipped);
    CHECK_EQ(filter.last_result().frame_index, before);
    // An earlier timestamp than the skipped frames': they were never counted.
    CHECK_EQ(filter.process(gray(places_pixels()[4]), 0.2).frame_index, before + 1);

    // Backends: the map's own works; another is a mismatch; NONE has no describer.
    options = topoloc::default_localizer_options();
    options.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    CHECK_EQ(topoloc::Localizer(map, options).process(gray(places_pixels()[6]), 0.0).place,
             uint32_t{6});
    options.image_backend = TOPOLOC_BACKEND_ONNX;
    CHECK_THROWS_STATUS((void)topoloc::Localizer(map, options), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.image_backend = TOPOLOC_BACKEND_NONE;
    topoloc::Localizer descriptors_only(map, options);
    try {
        (void)descriptors_only.process(gray(places_pixels()[0]), 0.0);
        report_failure(__FILE__, __LINE__, "NONE localizer described an image");
    } catch (const topoloc::NoDescriberError &e) {
        CHECK(e.status() == TOPOLOC_ERR_NO_DESCRIBER && !e.message().empty());
    }
    CHECK_EQ(descriptors_only.process(view2, 0.0).place, uint32_t{2});
    // A map built from descriptors has no describer.
    topoloc::Localizer plain(chain_map());
    CHECK_THROWS_STATUS(plain.process(gray(places_pixels()[0]), 0.0), TOPOLOC_ERR_NO_DESCRIBER);
    options.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    CHECK_THROWS_STATUS((void)topoloc::Localizer(chain_map(), options), TOPOLOC_ERR_NO_DESCRIBER);

    // Geometric verification: the image map stores keypoints, a map from descriptors does not.
    options = topoloc::default_localizer_options();
    options.verify_candidates = 3;
    topoloc::Localizer verifying(map, options);
    const topoloc::Result &checked = verifying.process(gray(places_pixels()[6]), 0.0);
    CHECK(checked.place == 6 && checked.verified && checked.inliers >= 20);
    CHECK_THROWS_STATUS((void)topoloc::Localizer(chain_map(), options), TOPOLOC_ERR_INVALID_OPTION);
}

void write_pgm(const std::string &path, const std::vector<uint8_t> &px)
{
    std::ofstream out(path, std::ios::binary);
    out << "P5\n" << kImgW << " " << kImgH << "\n255\n";
    out.write(reinterpret_cast<const char *>(px.data()), static_cast<std::streamsize>(px.size()));
}

TEST(image_files)
{
    TempDir dir;
    std::vector<std::string> paths;
    for (uint32_t p = 0; p < 4; ++p) {
        paths.push_back((dir.path / ("place " + std::to_string(p) + ".pgm")).string());
        write_pgm(paths.back(), places_pixels()[p]);
    }
    int calls = 0;
    const topoloc::Map map = topoloc::Map::build_from_image_files(
        paths, vlad_options(4), [&](topoloc::Stage, std::size_t, std::size_t total) {
            ++calls;
            return total > 0;
        });
    CHECK(calls >= 2);
    CHECK_EQ(map.place_count(), std::size_t{4});
    for (uint32_t v = 0; v < 4; ++v)
        CHECK(map.view_image(v) == paths[v]);
    topoloc::Localizer localizer(map);
    CHECK_EQ(localizer.process(gray(revisit_pixels(places_pixels()[1], 3)), 0.0).place,
             uint32_t{1});

    // No progress callback.
    CHECK_EQ(topoloc::Map::build_from_image_files(paths, vlad_options(4)).view_count(),
             std::size_t{4});

    std::vector<std::string> missing = paths;
    missing[3] = (dir.path / "no-such-image.png").string();
    const std::string message = CHECK_THROWS_STATUS(
        topoloc::Map::build_from_image_files(missing, vlad_options(4)), TOPOLOC_ERR_INVALID_IMAGE);
    CHECK(message.find(missing[3]) != std::string::npos);
    try {
        (void)topoloc::Map::build_from_image_files(missing, vlad_options(4));
    } catch (const topoloc::InvalidImageError &) {
        CHECK(true);
    }

    // ONNX with a model file that does not exist: the path is named.
    topoloc::ImageMapOptions onnx = topoloc::default_image_map_options();
    CHECK(onnx.backend == TOPOLOC_BACKEND_AUTO); // = ONNX for building
    const std::string model = (dir.path / "no-such-model.onnx").string();
    onnx.onnx_model_path = model.c_str();
    onnx.dim = 3;
    const std::string onnx_message = CHECK_THROWS_STATUS(
        topoloc::Map::build_from_image_files(paths, onnx), TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK(onnx_message.find(model) != std::string::npos);
}

} // namespace

int main() { return run_all_tests(); }
