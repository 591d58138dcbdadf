// The C++ side of the find_package consumer: uses the installed header-only RAII layer
// (topoloc.hpp) over the installed shared library. Builds a small map, saves and reloads it,
// localizes a few frames, and checks that failures surface as topoloc::Error. Exits non-zero on
// any failure.
#include <topoloc.hpp>

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

namespace {

int failures = 0;

#define EXPECT(cond)                                                                               \
    do {                                                                                           \
        if (!(cond)) {                                                                             \
            ++failures;                                                                            \
            std::fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);          \
        }                                                                                          \
    } while (0)

constexpr uint32_t kDim = 8;
constexpr uint32_t kPlaces = 3;
constexpr uint32_t kViewsPerPlace = 2;

std::vector<float> view_descriptor(uint32_t place, uint32_t view)
{
    std::vector<float> d(kDim, 0.05f);
    d[2 * place] = 1.0f;
    d[2 * place + 1] = view == 0 ? 0.3f : -0.3f;
    return d;
}

std::string temp_path()
{
    const char *tmp = std::getenv("TMPDIR");
    return std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") + "/topoloc-consumer-cpp-" +
           std::to_string(static_cast<long>(getpid())) + ".map";
}

void run()
{
    EXPECT(topoloc::abi_matches());
    EXPECT(std::string(topoloc::version()) == TOPOLOC_VERSION_STRING);

    topoloc::MapBuilder builder("consumer-desc", "v1", kDim);
    for (uint32_t p = 0; p < kPlaces; ++p) {
        EXPECT(builder.add_place(topoloc::Position{3.0 * p, 0.0, 0.0}) == p);
        for (uint32_t v = 0; v < kViewsPerPlace; ++v) {
            topoloc::ViewAttributes attributes;
            attributes.keyframe_id = 100 + p * kViewsPerPlace + v;
            attributes.image = "img/" + std::to_string(p) + "_" + std::to_string(v) + ".png";
            builder.add_view(p, view_descriptor(p, v), attributes);
        }
        if (p > 0) {
            builder.add_edge(p - 1, p);
        }
    }

    const std::string path = temp_path();
    builder.build().save(path);
    topoloc::Map map = topoloc::Map::load(path);
    std::remove(path.c_str());
    EXPECT(map.place_count() == kPlaces);
    EXPECT(map.view_count() == kPlaces * kViewsPerPlace);
    EXPECT(map.edge_count() == kPlaces - 1);
    EXPECT(map.dim() == kDim);
    EXPECT(map.descriptor_kind() == "consumer-desc");
    EXPECT(map.descriptor_model() == "v1");
    EXPECT(map.neighbours(1).size() == 2);
    EXPECT(map.view_image(3) == "img/1_1.png");
    EXPECT(map.view_info(3).keyframe_id.value_or(0) == 103);

    // Moves transfer ownership; the moved-from owner is empty.
    topoloc::Map moved = std::move(map);
    EXPECT(!map);
    EXPECT(static_cast<bool>(moved));

    topoloc::Localizer localizer(moved);
    for (uint32_t k = 0; k < 2 * kPlaces; ++k) {
        const uint32_t place = k / 2;
        std::vector<float> d = view_descriptor(place, k % 2);
        d[kDim - 1] += 0.02f;
        const topoloc::Result &r = localizer.process(d, 0.5 * k);
        EXPECT(r.frame_index == k);
        EXPECT(r.place == place);
        EXPECT(r.view == place * kViewsPerPlace + k % 2);
        EXPECT(!r.off_map);
        EXPECT(r.candidates.size() == kPlaces);
        EXPECT(!r.candidates.empty() && r.candidates[0].place == place);
    }

    // Errors are exceptions carrying the C status and message; the localizer is unchanged.
    bool threw = false;
    try {
        (void)localizer.process(std::vector<float>(kDim - 1, 1.0f), 100.0);
    } catch (const topoloc::Error &e) {
        threw = true;
        EXPECT(e.status() == TOPOLOC_ERR_DIMENSION_MISMATCH);
        EXPECT(!e.message().empty());
    }
    EXPECT(threw);
    EXPECT(localizer.process(view_descriptor(0, 0), 100.0).frame_index == 2 * kPlaces);

    threw = false;
    try {
        (void)topoloc::Map::load(path + ".missing");
    } catch (const topoloc::Error &e) {
        threw = true;
        EXPECT(e.status() == TOPOLOC_ERR_IO);
    }
    EXPECT(threw);
}

} // namespace

int main()
{
    try {
        run();
    } catch (const std::exception &e) {
        std::fprintf(stderr, "consumer (C++): unexpected exception: %s\n", e.what());
        return 1;
    }
    if (failures != 0) {
        std::fprintf(stderr, "consumer (C++): %d checks failed\n", failures);
        return 1;
    }
    std::printf("consumer (C++): ok (topoloc %s)\n", topoloc::version());
    return 0;
}
