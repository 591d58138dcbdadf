// localize_stream: what a SLAM host does with topoloc, in C++.
//
//   localize_stream            build a small demo map in memory, then localize a camera in it
//   localize_stream MAP        load MAP (a .topoloc file), then localize a camera in it
//
// A real host computes one global descriptor per frame with its own network (or topoloc's) and
// passes its visual-inertial odometry along. To stay self-contained, this example plays the
// camera itself: it drives along the map's places and "observes" a noisy copy of a stored view
// descriptor, just as a revisit under changed conditions would look.

#include <topoloc.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <random>
#include <vector>

namespace {

// The demo map: a corridor of places 2 m apart, four views each (one per yaw direction), with
// random unit descriptors standing in for a real descriptor network's output.
topoloc::Map build_demo_map(uint32_t places, uint32_t dim, std::mt19937 &rng)
{
    std::normal_distribution<float> gauss(0.f, 1.f);
    topoloc::MapBuilder builder("demo", "random-v1", dim);
    for (uint32_t p = 0; p < places; ++p) {
        const uint32_t place = builder.add_place(topoloc::Position{2.0 * p, 0.0, 0.0});
        for (uint32_t v = 0; v < 4; ++v) {
            std::vector<float> descriptor(dim);
            for (float &x : descriptor)
                x = gauss(rng); // normalised by topoloc
            topoloc::ViewAttributes attributes;
            attributes.keyframe_id = 100 * p + v; // the host's keyframe id, returned in results
            builder.add_view(place, descriptor, attributes);
        }
        if (p > 0)
            builder.add_edge(p - 1, p); // the robot can drive between neighbours
    }
    return builder.build();
}

// The host's per-frame descriptor: here, a stored view of `place` plus noise.
std::vector<float> camera_descriptor(const topoloc::Map &map, uint32_t place, uint32_t frame,
                                     std::mt19937 &rng)
{
    const std::vector<uint32_t> views = map.place_views(place);
    std::vector<float> d = map.view_descriptor(views[frame % views.size()]);
    std::normal_distribution<float> noise(0.f, 0.6f / std::sqrt(static_cast<float>(d.size())));
    for (float &x : d)
        x += noise(rng);
    return d;
}

// A path through the graph: start at place 0, keep moving to the first unvisited neighbour.
std::vector<uint32_t> drive_route(const topoloc::Map &map, std::size_t max_places)
{
    std::vector<bool> visited(map.place_count(), false);
    std::vector<uint32_t> route{0};
    visited[0] = true;
    while (route.size() < max_places) {
        bool moved = false;
        for (const uint32_t next : map.neighbours(route.back())) {
            if (!visited[next]) {
                visited[next] = true;
                route.push_back(next);
                moved = true;
                break;
            }
        }
        if (!moved)
            break;
    }
    return route;
}

} // namespace

int main(int argc, char **argv)
{
    if (!topoloc::abi_matches()) {
        std::fprintf(stderr, "libtopoloc %s has ABI %u, this program was built for ABI %u\n",
                     topoloc::version(), topoloc::abi_version(), topoloc::header_abi_version);
        return 2;
    }
    std::mt19937 rng(42);
    try {
        // 1. The map: loaded from a file made offline, or built here.
        const topoloc::Map map =
            argc > 1 ? topoloc::Map::load(argv[1]) : build_demo_map(12, 256, rng);
        std::printf(
            "topoloc %s: map with %zu places, %zu views, %zu edges, descriptor %s/%s D=%u\n",
            topoloc::version(), map.place_count(), map.view_count(), map.edge_count(),
            map.descriptor_kind().c_str(), map.descriptor_model().c_str(), map.dim());

        // 2. One localizer per camera. It keeps the map alive and allocates nothing per frame.
        topoloc::LocalizerOptions options = topoloc::default_localizer_options();
        options.top_k = 3;
        topoloc::Localizer localizer(map, options);

        // The camera's route: from place 0 along graph edges to unvisited neighbours (at most 10).
        const std::vector<uint32_t> route = drive_route(map, 10);

        // 3. The frame loop: one descriptor (and optionally odometry) per frame at 10 Hz; the
        //    camera dwells three frames at each place of its route.
        for (uint32_t frame = 0; frame < 3 * route.size(); ++frame) {
            const uint32_t truth = route[frame / 3];
            const std::vector<float> descriptor = camera_descriptor(map, truth, frame, rng);
            const double timestamp = 0.1 * frame;
            const topoloc::Result &r = localizer.process(descriptor, timestamp);

            std::printf("frame %2llu  t=%.1fs  true place %2u  ->  place %2u view %3u  sim %.2f  "
                        "conf %.2f%s  |",
                        static_cast<unsigned long long>(r.frame_index), timestamp, truth, r.place,
                        r.view, r.similarity, r.confidence, r.off_map ? "  OFF-MAP" : "");
            for (const topoloc::Candidate &c : r.candidates) {
                std::printf("  %u:%.2f", c.place, c.probability);
            }
            std::printf("\n");

            // A host would use the answer here: e.g. hand map.view_info(r.view).keyframe_id to its
            // loop-closure module when r.confidence is high and !r.off_map.
        }
        return 0;
    } catch (const topoloc::Error &e) {
        // Every failure carries the C status code and the library's message.
        std::fprintf(stderr, "topoloc error %u: %s\n", static_cast<unsigned>(e.status()), e.what());
        return 1;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "error: %s\n", e.what());
        return 1;
    }
}
