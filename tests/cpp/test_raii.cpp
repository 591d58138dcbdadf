// Tests of the C++ RAII layer (include/topoloc.hpp): ownership and moves, exceptions carrying
// the C status and message, the full builder -> save -> load -> localize flow, a localizer that
// outlives its Map owner, and the ABI check. Built and run by tests/cpp/run.sh, normally and
// under ASan+UBSan (which is what turns a double free or a leak into a failure).

#include "topoloc.hpp"
#include "topoloc.hpp"  // deliberately twice: the include guard must make this harmless

#include <stdlib.h>  // mkdtemp (POSIX)

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

// ---------------------------------------------------------------------------------------------
// A tiny harness: CHECK records a failure and goes on; a test fails if any CHECK failed or it
// threw. The last line printed is exactly "N passed, M failed".
// ---------------------------------------------------------------------------------------------

namespace {

std::atomic<int> g_check_failures{0};  // atomic: CHECK is also used on worker threads

void report_failure(const char *file, int line, const std::string &what) {
  std::printf("    %s:%d: CHECK failed: %s\n", file, line, what.c_str());
  ++g_check_failures;
}

#define CHECK(cond)                                                                            \
  do {                                                                                         \
    if (!(cond)) report_failure(__FILE__, __LINE__, #cond);                                    \
  } while (0)

#define CHECK_EQ(a, b)                                                                         \
  do {                                                                                         \
    const auto check_a_ = (a);                                                                 \
    const auto check_b_ = (b);                                                                 \
    if (!(check_a_ == check_b_))                                                               \
      report_failure(__FILE__, __LINE__,                                                       \
                     std::string(#a " == " #b "  (") + std::to_string(check_a_) + " vs " +      \
                         std::to_string(check_b_) + ")");                                      \
  } while (0)

// Runs `body`, expecting a topoloc::Error with `status`; returns its message ("" otherwise).
#define CHECK_THROWS_STATUS(body, expected_status)                                             \
  ([&]() -> std::string {                                                                      \
    try {                                                                                      \
      body;                                                                                    \
    } catch (const topoloc::Error &e) {                                                        \
      if (e.status() != (expected_status))                                                     \
        report_failure(__FILE__, __LINE__,                                                     \
                       std::string(#body " threw status ") +                                   \
                           std::to_string(static_cast<unsigned>(e.status())) + " (" +          \
                           e.what() + "), expected " #expected_status);                        \
      return e.message();                                                                      \
    }                                                                                          \
    report_failure(__FILE__, __LINE__, #body " did not throw " #expected_status);              \
    return std::string();                                                                      \
  }())

struct Test {
  const char *name;
  std::function<void()> body;
};

std::vector<Test> &registry() {
  static std::vector<Test> tests;
  return tests;
}

struct Register {
  Register(const char *name, std::function<void()> body) {
    registry().push_back({name, std::move(body)});
  }
};

#define TEST(name)                                                                             \
  void test_##name();                                                                          \
  const Register register_##name(#name, test_##name);                                          \
  void test_##name()

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

constexpr uint32_t kDim = 64;
constexpr uint32_t kPlaces = 6;
constexpr uint32_t kViews = 4;

// Deterministic pseudo-random unit vector (xorshift), so the tests need no RNG state.
std::vector<float> unit_vector(uint64_t seed, uint32_t dim = kDim) {
  uint64_t state = seed * 0x9E3779B97F4A7C15ull | 1u;
  std::vector<float> v(dim);
  double norm = 0;
  for (auto &x : v) {
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    x = static_cast<float>(static_cast<double>(state >> 40) / double(1u << 24) - 0.5);
    norm += double(x) * x;
  }
  for (auto &x : v) x = static_cast<float>(x / std::sqrt(norm));
  return v;
}

// `a + scale * b` (not normalised: the library normalises).
std::vector<float> mix(const std::vector<float> &a, const std::vector<float> &b, float scale) {
  std::vector<float> v(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) v[i] = a[i] + scale * b[i];
  return v;
}

float dot(const std::vector<float> &a, const std::vector<float> &b) {
  float s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

std::vector<float> view_descriptor_seed(uint32_t place, uint32_t view) {
  return unit_vector(1000 + place * 16 + view);
}

topoloc::Pose pose_at(double x, double yaw) {
  const double c = std::cos(yaw), s = std::sin(yaw);
  return {c, -s, 0, x, s, c, 0, 0, 0, 0, 1, 1.5, 0, 0, 0, 1};
}

// A chain of kPlaces places 2 m apart along x, kViews views each, with keyframe ids, poses, and
// images on even views; edges between consecutive places.
topoloc::MapBuilder chain_builder() {
  topoloc::MapBuilder builder("test", "chain-v1", kDim);
  for (uint32_t p = 0; p < kPlaces; ++p) {
    const uint32_t place = builder.add_place(topoloc::Position{2.0 * p, 0.0, 0.0});
    for (uint32_t v = 0; v < kViews; ++v) {
      topoloc::ViewAttributes attributes;
      attributes.keyframe_id = p * 100 + v;
      attributes.world_T_camera = pose_at(2.0 * p, 1.5707963267948966 * v);
      if (v % 2 == 0) attributes.image = "images/place" + std::to_string(p) + "_view" +
                                         std::to_string(v) + ".png";
      builder.add_view(place, view_descriptor_seed(p, v), attributes);
    }
    if (p > 0) builder.add_edge(p - 1, p, 1.0f);
  }
  return builder;
}

topoloc::Map chain_map() { return chain_builder().build(); }

// A noisy observation of `place` (its view `frame % kViews`), as a camera would give.
std::vector<float> observe(uint32_t place, uint32_t frame) {
  return mix(view_descriptor_seed(place, frame % kViews), unit_vector(50000 + frame), 0.35f);
}

// A fresh temporary directory, removed at destruction.
struct TempDir {
  std::filesystem::path path;
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "topoloc-cpp-XXXXXX").string();
    if (mkdtemp(&pattern[0]) == nullptr) throw std::runtime_error("mkdtemp failed");
    path = pattern;
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
  TempDir(const TempDir &) = delete;
  TempDir &operator=(const TempDir &) = delete;
};

template <typename T> void assign_from(T &target, T &source) { target = std::move(source); }

// Walks the chain 0 -> kPlaces-1, three frames per place; returns how many frames were
// localized at the true place, and checks every result's invariants.
int walk(topoloc::Localizer &localizer, double t0 = 0.0) {
  int correct = 0;
  for (uint32_t i = 0; i < kPlaces * 3; ++i) {
    const uint32_t truth = i / 3;
    const topoloc::Result &r = localizer.process(observe(truth, i), t0 + 0.1 * i);
    CHECK_EQ(r.frame_index, uint64_t{i});
    CHECK(!r.off_map);
    CHECK(r.confidence > 0.f && r.confidence <= 1.f);
    CHECK(!r.candidates.empty());
    if (!r.candidates.empty()) {
      CHECK_EQ(r.candidates[0].place, r.place);
      CHECK_EQ(r.candidates[0].view, r.view);
    }
    for (std::size_t c = 1; c < r.candidates.size(); ++c)
      CHECK(r.candidates[c - 1].probability >= r.candidates[c].probability);
    if (r.place == truth) ++correct;
  }
  return correct;
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

TEST(abi_and_version) {
  CHECK(topoloc::abi_matches());
  CHECK_EQ(topoloc::abi_version(), uint32_t{TOPOLOC_ABI_VERSION});
  CHECK_EQ(topoloc::header_abi_version, uint32_t{TOPOLOC_ABI_VERSION});
  CHECK(std::string(topoloc::version()) == TOPOLOC_VERSION_STRING);
  CHECK(std::string(topoloc::status_string(TOPOLOC_ERR_IO)) == "I/O error");
}

TEST(owners_are_move_only) {
  static_assert(!std::is_copy_constructible_v<topoloc::Map>);
  static_assert(!std::is_copy_assignable_v<topoloc::Map>);
  static_assert(std::is_nothrow_move_constructible_v<topoloc::Map>);
  static_assert(std::is_nothrow_move_assignable_v<topoloc::Map>);
  static_assert(!std::is_copy_constructible_v<topoloc::MapBuilder>);
  static_assert(!std::is_copy_assignable_v<topoloc::MapBuilder>);
  static_assert(std::is_nothrow_move_constructible_v<topoloc::MapBuilder>);
  static_assert(std::is_nothrow_move_assignable_v<topoloc::MapBuilder>);
  static_assert(!std::is_copy_constructible_v<topoloc::Localizer>);
  static_assert(!std::is_copy_assignable_v<topoloc::Localizer>);
  static_assert(std::is_nothrow_move_constructible_v<topoloc::Localizer>);
  static_assert(std::is_nothrow_move_assignable_v<topoloc::Localizer>);
  static_assert(!std::is_convertible_v<topoloc::Map, bool>, "operator bool must be explicit");
  CHECK(true);
}

TEST(map_moves) {
  topoloc::Map a = chain_map();
  CHECK(static_cast<bool>(a));
  const topoloc_map *raw = a.capi();

  topoloc::Map b(std::move(a));  // move construction
  CHECK(!a);
  CHECK(a.capi() == nullptr);
  CHECK(b.capi() == raw);
  CHECK_EQ(b.place_count(), std::size_t{kPlaces});

  topoloc::Map c = chain_map();  // move assignment over a live map frees the old one (ASan)
  c = std::move(b);
  CHECK(!b);
  CHECK(c.capi() == raw);

  assign_from(c, c);  // self-move-assignment keeps the map
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

TEST(builder_moves) {
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

TEST(localizer_moves) {
  const topoloc::Map map = chain_map();
  topoloc::Localizer a(map);
  const topoloc_localizer *raw = a.capi();
  a.process(observe(0, 0), 0.0);

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

TEST(dimension_mismatch_throws) {
  const topoloc::Map map = chain_map();
  topoloc::Localizer localizer(map);
  const topoloc::Result first = localizer.process(observe(1, 0), 0.0);

  const std::vector<float> short_descriptor(kDim - 1, 0.5f);
  const std::string message =
      CHECK_THROWS_STATUS(localizer.process(short_descriptor, 0.1), TOPOLOC_ERR_DIMENSION_MISMATCH);
  CHECK(!message.empty());
  CHECK(message.find(std::to_string(kDim)) != std::string::npos);  // names the expected D

  // what() = status description + message.
  try {
    localizer.process(short_descriptor, 0.1);
  } catch (const topoloc::Error &e) {
    const std::string what = e.what();
    CHECK(what.find("descriptor dimension mismatch") == 0);
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

TEST(other_statuses_throw) {
  const topoloc::Map map = chain_map();
  topoloc::Localizer localizer(map);
  localizer.process(observe(0, 0), 1.0);
  CHECK_THROWS_STATUS(localizer.process(observe(0, 1), 0.5), TOPOLOC_ERR_TIMESTAMP);
  CHECK_THROWS_STATUS(localizer.process(std::vector<float>(kDim, 0.f), 2.0),
                      TOPOLOC_ERR_ZERO_DESCRIPTOR);
  std::vector<float> nan_descriptor = observe(0, 1);
  nan_descriptor[3] = std::nanf("");
  CHECK_THROWS_STATUS(localizer.process(nan_descriptor, 2.0), TOPOLOC_ERR_NON_FINITE);
  topoloc::Pose not_rigid = pose_at(0, 0);
  not_rigid[0] = 2.0;  // scales x
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
  topoloc::LocalizerOptions unset{};  // struct_size 0: not filled by the _default function
  CHECK_THROWS_STATUS((void)topoloc::Localizer(map, unset), TOPOLOC_ERR_STRUCT_SIZE);

  topoloc::MapBuilder builder("test", "", kDim);
  builder.add_place();
  CHECK_THROWS_STATUS(builder.build(), TOPOLOC_ERR_INVALID_MAP);  // a place without views
  CHECK_THROWS_STATUS((void)topoloc::MapBuilder("", "", kDim), TOPOLOC_ERR_INVALID_ARGUMENT);
  CHECK_THROWS_STATUS(topoloc::MapBuilder("test", "", kDim).build(), TOPOLOC_ERR_EMPTY_MAP);

  // check() itself.
  topoloc::check(TOPOLOC_OK);
  CHECK_THROWS_STATUS(topoloc::check(TOPOLOC_ERR_PANIC), TOPOLOC_ERR_PANIC);
}

TEST(missing_file_throws_io) {
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
  CHECK(topoloc::last_error_message() == long_message);  // reading does not consume it

  // Saving into a directory that does not exist fails with IO too.
  const topoloc::Map map = chain_map();
  CHECK_THROWS_STATUS(map.save((dir.path / "missing" / "m.topoloc").string()), TOPOLOC_ERR_IO);
}

TEST(full_flow_build_save_load_localize) {
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
  if (position) CHECK_EQ((*position)[0], 6.0);

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
    if (!info.keyframe_id || !info.world_T_camera) continue;
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
}

TEST(localizer_outlives_map_owner) {
  TempDir dir;
  const std::string path = (dir.path / "chain.topoloc").string();
  chain_map().save(path);

  std::optional<topoloc::Localizer> localizer;
  {
    topoloc::Map map = topoloc::Map::load(path);
    localizer.emplace(map);
  }  // the Map owner is destroyed here; the localizer holds its own reference
  CHECK_EQ(walk(*localizer), int(kPlaces * 3));
  localizer.reset();  // frees the localizer and with it the last reference to the map
  CHECK(!localizer.has_value());
}

TEST(map_from_keyframes) {
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

  keyframes[5].descriptor.pop_back();  // the message names the bad keyframe
  const std::string message = CHECK_THROWS_STATUS(
      topoloc::map_from_keyframes("test", "kf-v1", kDim, keyframes), TOPOLOC_ERR_INVALID_ARGUMENT);
  CHECK(message.find("keyframe 5") != std::string::npos);
  CHECK_THROWS_STATUS(topoloc::map_from_keyframes("test", "", kDim, {}), TOPOLOC_ERR_EMPTY_MAP);
}

TEST(capi_interop) {
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

TEST(threads_share_one_map) {
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
            if (e.status() == TOPOLOC_ERR_IO && e.message().find(path) != std::string::npos)
              ++good_messages[t];
          }
          (void)map.view_descriptor(static_cast<uint32_t>(round));  // concurrent const reads
          localizer.reset();
          correct[t] += walk(localizer);
        }
      } catch (const std::exception &e) {
        report_failure(__FILE__, __LINE__, std::string("thread threw: ") + e.what());
      }
    });
  }
  for (std::thread &thread : threads) thread.join();
  for (int t = 0; t < kThreads; ++t) {
    CHECK_EQ(correct[t], int(5 * kPlaces * 3));
    CHECK_EQ(good_messages[t], 5);
  }
}

#ifdef CV_VERSION
TEST(opencv_overloads) {
  const topoloc::Map map = chain_map();
  topoloc::Localizer localizer(map);
  std::vector<float> d = observe(2, 0);
  const cv::Mat row(1, static_cast<int>(kDim), CV_32F, d.data());
  CHECK_EQ(localizer.process(row, 0.0).place, uint32_t{2});
  const cv::Mat col(static_cast<int>(kDim), 1, CV_32F, d.data());
  CHECK_EQ(localizer.process(col, 0.1).place, uint32_t{2});
  CHECK_THROWS_STATUS(localizer.process(cv::Mat(1, static_cast<int>(kDim), CV_64F), 0.2),
                      TOPOLOC_ERR_INVALID_ARGUMENT);
  CHECK_THROWS_STATUS(localizer.process(cv::Mat(8, 8, CV_32F, d.data()), 0.2),
                      TOPOLOC_ERR_INVALID_ARGUMENT);
  CHECK_THROWS_STATUS(localizer.process(cv::Mat(), 0.2), TOPOLOC_ERR_INVALID_ARGUMENT);
  const cv::Mat wide(4, static_cast<int>(kDim), CV_32F, cv::Scalar(1.0));
  CHECK_THROWS_STATUS(localizer.process(wide.col(0), 0.2), TOPOLOC_ERR_INVALID_ARGUMENT);
  topoloc::MapBuilder builder("test", "", kDim);
  CHECK_EQ(builder.add_view(builder.add_place(), row), uint32_t{0});
}
#endif

}  // namespace

int main() {
  int passed = 0, failed = 0;
  for (const Test &test : registry()) {
    const int before = g_check_failures.load();
    bool ok = true;
    try {
      test.body();
    } catch (const std::exception &e) {
      std::printf("    unexpected exception: %s\n", e.what());
      ok = false;
    } catch (...) {
      std::printf("    unexpected non-standard exception\n");
      ok = false;
    }
    ok = ok && g_check_failures == before;
    std::printf("%s %s\n", ok ? "PASS" : "FAIL", test.name);
    (ok ? passed : failed) += 1;
  }
  std::printf("%d passed, %d failed\n", passed, failed);
  return failed == 0 ? 0 : 1;
}
