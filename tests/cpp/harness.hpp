// Shared harness and fixtures of the C++ layer tests (test_raii.cpp, test_status.cpp,
// test_loops.cpp, test_loop_images.cpp, test_pose_fix.cpp, test_opencv.cpp): CHECK macros, a test registry, and small
// maps and images built from deterministic data. Include it after topoloc.hpp; every function is inline so that
// each test program uses what it needs.
#ifndef TOPOLOC_TESTS_CPP_HARNESS_HPP
#define TOPOLOC_TESTS_CPP_HARNESS_HPP

#include "topoloc.hpp"

#include <stdlib.h> // mkdtemp (POSIX)

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

// ---------------------------------------------------------------------------------------------
// A tiny harness: CHECK records a failure and goes on; a test fails if any CHECK failed or it
// threw. The last line printed is exactly "N passed, M failed".
// ---------------------------------------------------------------------------------------------

inline std::atomic<int> g_check_failures{0}; // atomic: CHECK is also used on worker threads

inline void report_failure(const char *file, int line, const std::string &what)
{
    std::printf("    %s:%d: CHECK failed: %s\n", file, line, what.c_str());
    ++g_check_failures;
}

#define CHECK(cond)                                                                                \
    do {                                                                                           \
        if (!(cond))                                                                               \
            report_failure(__FILE__, __LINE__, #cond);                                             \
    } while (0)

#define CHECK_EQ(a, b)                                                                             \
    do {                                                                                           \
        const auto check_a_ = (a);                                                                 \
        const auto check_b_ = (b);                                                                 \
        if (!(check_a_ == check_b_))                                                               \
            report_failure(__FILE__, __LINE__,                                                     \
                           std::string(#a " == " #b "  (") + std::to_string(check_a_) + " vs " +   \
                               std::to_string(check_b_) + ")");                                    \
    } while (0)

// Runs `body`, expecting a topoloc::Error with `status`; returns its message ("" otherwise).
#define CHECK_THROWS_STATUS(body, expected_status)                                                 \
    ([&]() -> std::string {                                                                        \
        try {                                                                                      \
            static_cast<void>(body);                                                               \
        } catch (const topoloc::Error &e) {                                                        \
            if (e.status() != (expected_status))                                                   \
                report_failure(__FILE__, __LINE__,                                                 \
                               std::string(#body " threw status ") +                               \
                                   std::to_string(static_cast<unsigned>(e.status())) + " (" +      \
                                   e.what() + "), expected " #expected_status);                    \
            return e.message();                                                                    \
        }                                                                                          \
        report_failure(__FILE__, __LINE__, #body " did not throw " #expected_status);              \
        return std::string();                                                                      \
    }())

struct Test {
    const char *name;
    std::function<void()> body;
};

inline std::vector<Test> &registry()
{
    static std::vector<Test> tests;
    return tests;
}

struct Register {
    Register(const char *name, std::function<void()> body)
    {
        registry().push_back({name, std::move(body)});
    }
};

#define TEST(name)                                                                                 \
    void test_##name();                                                                            \
    const Register register_##name(#name, test_##name);                                            \
    void test_##name()

// ---------------------------------------------------------------------------------------------
// Fixtures
// ---------------------------------------------------------------------------------------------

constexpr uint32_t kDim = 64;
constexpr uint32_t kPlaces = 6;
constexpr uint32_t kViews = 4;

// Deterministic pseudo-random unit vector (xorshift), so the tests need no RNG state.
inline std::vector<float> unit_vector(uint64_t seed, uint32_t dim = kDim)
{
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
    for (auto &x : v)
        x = static_cast<float>(x / std::sqrt(norm));
    return v;
}

// `a + scale * b` (not normalised: the library normalises).
inline std::vector<float> mix(const std::vector<float> &a, const std::vector<float> &b, float scale)
{
    std::vector<float> v(a.size());
    for (std::size_t i = 0; i < a.size(); ++i)
        v[i] = a[i] + scale * b[i];
    return v;
}

inline float dot(const std::vector<float> &a, const std::vector<float> &b)
{
    float s = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        s += a[i] * b[i];
    return s;
}

inline std::vector<float> view_descriptor_seed(uint32_t place, uint32_t view)
{
    return unit_vector(1000 + place * 16 + view);
}

inline topoloc::Pose pose_at(double x, double yaw)
{
    const double c = std::cos(yaw), s = std::sin(yaw);
    return {c, -s, 0, x, s, c, 0, 0, 0, 0, 1, 1.5, 0, 0, 0, 1};
}

// A chain of kPlaces places 2 m apart along x, kViews views each, with keyframe ids, poses, and
// images on even views; edges between consecutive places.
inline topoloc::MapBuilder chain_builder()
{
    topoloc::MapBuilder builder("test", "chain-v1", kDim);
    for (uint32_t p = 0; p < kPlaces; ++p) {
        const uint32_t place = builder.add_place(topoloc::Position{2.0 * p, 0.0, 0.0});
        for (uint32_t v = 0; v < kViews; ++v) {
            topoloc::ViewAttributes attributes;
            attributes.keyframe_id = p * 100 + v;
            attributes.world_T_camera = pose_at(2.0 * p, 1.5707963267948966 * v);
            if (v % 2 == 0)
                attributes.image =
                    "images/place" + std::to_string(p) + "_view" + std::to_string(v) + ".png";
            builder.add_view(place, view_descriptor_seed(p, v), attributes);
        }
        if (p > 0)
            builder.add_edge(p - 1, p, 1.0f);
    }
    return builder;
}

topoloc::Map chain_map() { return chain_builder().build(); }

// A noisy observation of `place` (its view `frame % kViews`), as a camera would give.
inline std::vector<float> observe(uint32_t place, uint32_t frame)
{
    return mix(view_descriptor_seed(place, frame % kViews), unit_vector(50000 + frame), 0.35f);
}

// A fresh temporary directory, removed at destruction.
struct TempDir {
    std::filesystem::path path;
    TempDir()
    {
        std::string pattern =
            (std::filesystem::temp_directory_path() / "topoloc-cpp-XXXXXX").string();
        if (mkdtemp(&pattern[0]) == nullptr)
            throw std::runtime_error("mkdtemp failed");
        path = pattern;
    }
    ~TempDir()
    {
        std::error_code ignored;
        std::filesystem::remove_all(path, ignored);
    }
    TempDir(const TempDir &) = delete;
    TempDir &operator=(const TempDir &) = delete;
};

template <typename T> inline void assign_from(T &target, T &source) { target = std::move(source); }

// Walks the chain 0 -> kPlaces-1, three frames per place; returns how many frames were
// localized at the true place, and checks every result's invariants.
inline int walk(topoloc::Localizer &localizer, double t0 = 0.0)
{
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
        if (r.place == truth)
            ++correct;
    }
    return correct;
}

// ---------------------------------------------------------------------------------------------
// Images: small synthetic grey "places" (as tests/images.rs and tests/c), VLAD maps (no model)
// ---------------------------------------------------------------------------------------------

constexpr uint32_t kImgW = 160;
constexpr uint32_t kImgH = 120;
constexpr uint32_t kImgPlaces = 8;

inline uint64_t lcg(uint64_t &state)
{
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return state;
}

// A place: a grey ramp under 80 rectangles of random shades.
inline std::vector<uint8_t> place_pixels(uint64_t seed)
{
    uint64_t state = seed * 0x9E3779B97F4A7C15ull + 7;
    auto below = [&state](uint32_t m) { return static_cast<uint32_t>((lcg(state) >> 33) % m); };
    std::vector<uint8_t> px(kImgW * kImgH);
    for (uint32_t i = 0; i < px.size(); ++i)
        px[i] = uint8_t((i % kImgW) * 255 / kImgW / 2 + 40);
    for (int k = 0; k < 80; ++k) {
        const uint32_t x0 = below(kImgW), y0 = below(kImgH), w = 4 + below(30), h = 4 + below(30);
        const uint8_t shade = uint8_t(below(256));
        for (uint32_t y = y0; y < std::min(y0 + h, kImgH); ++y)
            for (uint32_t x = x0; x < std::min(x0 + w, kImgW); ++x)
                px[y * kImgW + x] = shade;
    }
    return px;
}

// The place seen again: shifted by 2 pixels, brighter, noisy.
inline std::vector<uint8_t> revisit_pixels(const std::vector<uint8_t> &in, uint64_t seed)
{
    std::vector<uint8_t> out(in.size());
    uint64_t state = seed;
    for (uint32_t y = 0; y < kImgH; ++y)
        for (uint32_t x = 0; x < kImgW; ++x) {
            const uint32_t sx = std::min(x + 2, kImgW - 1);
            const int noise = int(lcg(state) >> 60) - 8;
            out[y * kImgW + x] =
                uint8_t(std::clamp(in[y * kImgW + sx] * 11 / 10 + 10 + noise, 0, 255));
        }
    return out;
}

inline const std::vector<std::vector<uint8_t>> &places_pixels()
{
    static const std::vector<std::vector<uint8_t>> all = [] {
        std::vector<std::vector<uint8_t>> v;
        for (uint32_t p = 0; p < kImgPlaces; ++p)
            v.push_back(place_pixels(p));
        return v;
    }();
    return all;
}

inline topoloc::Image gray(const std::vector<uint8_t> &px)
{
    return topoloc::image_view(px.data(), kImgW, kImgH, TOPOLOC_PIXEL_GRAY8);
}

inline topoloc::ImageMapOptions vlad_options(uint32_t images)
{
    topoloc::ImageMapOptions options = topoloc::default_image_map_options();
    options.backend = TOPOLOC_BACKEND_VLAD_ORB;
    options.dim = images - 1;
    options.threads = 1;
    options.vlad_clusters = 16;
    return options;
}

inline std::vector<topoloc::Image> place_images(uint32_t count = kImgPlaces)
{
    std::vector<topoloc::Image> images;
    for (uint32_t p = 0; p < count; ++p)
        images.push_back(gray(places_pixels()[p]));
    return images;
}

inline const topoloc::Map &image_map()
{
    static const topoloc::Map map =
        topoloc::Map::build_from_images(place_images(), vlad_options(kImgPlaces));
    return map;
}

// ---------------------------------------------------------------------------------------------
// Two views of the same keypoints (the generator of tests/c/test_loops.c), for loop tests
// ---------------------------------------------------------------------------------------------
constexpr std::size_t kLoopPoints = 60;

// kLoopPoints scene points 3-8 m in front of a 300-pixel pinhole camera (principal point
// 160, 120), seen from it (`first`) and from a camera 0.3 m to the right and 0.1 m ahead,
// turned 3 degrees (`second`); each point has the same random 32-byte descriptor in both views.
struct TwoViews {
    std::vector<float> first;         // 2 per point
    std::vector<float> second;        // 2 per point
    std::vector<uint8_t> descriptors; // 32 per point
    std::vector<float> scene;         // 3 per point, in the first camera's frame
};

inline const TwoViews &two_views()
{
    static const TwoViews views = [] {
        TwoViews v;
        uint32_t state = 12345u;
        const double c = 0.99862953475, s = 0.05233595624; // cos, sin of 3 degrees
        auto next = [&state] {
            state = state * 1664525u + 1013904223u;
            return static_cast<double>(state >> 8) / 16777216.0;
        };
        while (v.first.size() < 2 * kLoopPoints) {
            const double z = 3.0 + 5.0 * next();
            const double x = (next() - 0.5) * z;
            const double y = (next() - 0.5) * 0.7 * z;
            // The second camera: p' = R^T (p - t), R a yaw about y.
            const double qx = c * (x - 0.3) - s * (z - 0.1);
            const double qz = s * (x - 0.3) + c * (z - 0.1);
            const double u1 = 300.0 * x / z + 160.0, v1 = 300.0 * y / z + 120.0;
            const double u2 = 300.0 * qx / qz + 160.0, v2 = 300.0 * y / qz + 120.0;
            if (qz < 0.5 || u1 < 0 || u1 > 319 || v1 < 0 || v1 > 239 || u2 < 0 || u2 > 319 ||
                v2 < 0 || v2 > 239)
                continue;
            v.first.insert(v.first.end(), {float(u1), float(v1)});
            v.second.insert(v.second.end(), {float(u2), float(v2)});
            v.scene.insert(v.scene.end(), {float(x), float(y), float(z)});
            for (int b = 0; b < 32; ++b) {
                state = state * 1664525u + 1013904223u;
                v.descriptors.push_back(static_cast<uint8_t>(state >> 24));
            }
        }
        return v;
    }();
    return views;
}

struct CallbackFailure : std::exception {
    const char *what() const noexcept override { return "callback failure"; }
};

// Runs every registered test; prints "PASS name" / "FAIL name" and a last line
// "N passed, M failed". Returns the exit code: 0 when all passed.
inline int run_all_tests()
{
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

#endif // TOPOLOC_TESTS_CPP_HARNESS_HPP
