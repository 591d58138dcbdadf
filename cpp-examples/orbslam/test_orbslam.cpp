// Tests of topoloc_orbslam.hpp, the ORB-SLAM2/3 KeyFrameDatabase replacement, with stand-ins of
// ORB-SLAM's KeyFrame, Frame and MapPoint (their member names and getter shapes, nothing else):
// a revisit closes a loop through the ORB-SLAM2 and ORB-SLAM3 calls with the right keyframe and
// relative pose, relocalization ranks the right keyframe first, erase and clear forget
// keyframes, every bad input is reported without changing the database, confirmed hints come
// out once, and the tracking and loop closing threads may call it together.
//
// Build and run from the repository root: see cpp-examples/orbslam/README.md ("Test").

#include "topoloc_orbslam.hpp"

#include "../../tests/cpp/harness.hpp"

#include <opencv2/imgproc.hpp>

#include <deque>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

namespace {

namespace to = topoloc_orbslam;

constexpr double kF = 150.0, kCx = 80.0, kCy = 60.0; // a pinhole of the 160x120 images

// ---------------------------------------------------------------------------------------------
// Stand-ins of ORB-SLAM's classes
// ---------------------------------------------------------------------------------------------

// ORB-SLAM3's Map: its address, and whether it was discarded.
struct Map {
    bool bad = false;
    bool IsBad() { return bad; }
};

// What both ORB-SLAM versions' keyframes hold with the same names.
struct KeyFrameData {
    unsigned long mnId = 0;
    double mTimeStamp = 0.0;
    std::vector<cv::KeyPoint> mvKeysUn;
    cv::Mat mDescriptors;
    cv::Mat mImGray; // the member the integration adds (README.md)
    float fx = 0, fy = 0, cx = 0, cy = 0;
    bool mbBad = false;
    Map *mpMap = nullptr;
    to::Pose Tcw{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    bool has_pose = true;
    bool isBad() { return mbBad; }
    Map *GetMap() { return mpMap; }
};

struct Frame {
    unsigned long mnId = 0;
    double mTimeStamp = 0.0;
    cv::Mat mImGray; // the member the integration adds (README.md)
};

namespace orb2 { // cv::Mat poses and positions

struct MapPoint {
    std::array<double, 3> xyz{};
    bool bad = false;
    cv::Mat GetWorldPos()
    {
        return (cv::Mat_<float>(3, 1) << float(xyz[0]), float(xyz[1]), float(xyz[2]));
    }
    bool isBad() { return bad; }
};

struct KeyFrame : KeyFrameData {
    std::vector<MapPoint *> points;
    std::set<KeyFrame *> connected;
    cv::Mat GetPose() { return has_pose ? to::to_mat(Tcw) : cv::Mat(); }
    std::vector<MapPoint *> GetMapPointMatches() { return points; }
    std::set<KeyFrame *> GetConnectedKeyFrames() { return connected; }
};

} // namespace orb2

namespace orb3 { // Sophus / Eigen shaped poses and positions

struct Matrix4f {
    float m[16];
    float operator()(int r, int c) const { return m[4 * r + c]; }
};

struct SE3f {
    Matrix4f M;
    Matrix4f matrix() const { return M; }
};

struct Vector3f {
    float v[3];
    float operator()(int i) const { return v[i]; }
};

struct MapPoint {
    std::array<double, 3> xyz{};
    bool bad = false;
    Vector3f GetWorldPos() { return {{float(xyz[0]), float(xyz[1]), float(xyz[2])}}; }
    bool isBad() { return bad; }
};

// ORB-SLAM3's GeometricCamera: type 0 pinhole, 1 fisheye (here equidistant: a Kannala-Brandt
// model with k1..k4 = 0), anything else another model.
struct Camera {
    int type = 0;
    int GetType() const { return type; }
    Vector3f unprojectEig(const cv::Point2f &p) const
    {
        const double dx = (p.x - kCx) / kF, dy = (p.y - kCy) / kF;
        const double theta = std::hypot(dx, dy);
        const double s = theta > 1e-12 ? std::sin(theta) / theta : 1.0;
        return {{float(s * dx), float(s * dy), float(std::cos(theta))}};
    }
};

// A pinhole pixel of the test camera in the equidistant fisheye image.
cv::Point2f fisheye_pixel(const cv::Point2f &p)
{
    const double dx = (p.x - kCx) / kF, dy = (p.y - kCy) / kF;
    const double r = std::hypot(dx, dy);
    const double scale = r > 1e-12 ? std::atan(r) / r : 1.0;
    return {float(kCx + kF * scale * dx), float(kCy + kF * scale * dy)};
}

struct KeyFrame : KeyFrameData {
    std::vector<MapPoint *> points;
    SE3f GetPose()
    {
        SE3f T{};
        for (int i = 0; i < 16; ++i)
            T.M.m[i] = float(Tcw[std::size_t(i)]);
        return T;
    }
    std::set<KeyFrame *> connected;
    Camera camera;
    Camera *mpCamera = &camera;
    int NLeft = -1;
    std::vector<MapPoint *> GetMapPointMatches() { return points; }
    std::set<KeyFrame *> GetConnectedKeyFrames() { return connected; }
};

// The ORB-SLAM3 accessor of README.md, on the stand-ins.
struct Access : to::DefaultAccess<KeyFrame, Frame> {
    static std::optional<to::Pose> camera_from_world(KeyFrame &kf)
    {
        return to::pose_from_matrix(kf.GetPose().matrix());
    }
    static bool world_position(MapPoint *mp, std::array<double, 3> &out)
    {
        if (mp == nullptr || mp->isBad())
            return false;
        const Vector3f p = mp->GetWorldPos();
        out = {p(0), p(1), p(2)};
        return true;
    }
    static const void *map_of(KeyFrame &kf) { return kf.GetMap(); }
    static bool map_is_bad(KeyFrame &kf) { return kf.GetMap() != nullptr && kf.GetMap()->IsBad(); }
    static to::CameraModel camera_model(KeyFrame &kf)
    {
        switch (kf.mpCamera->GetType()) {
        case 0:
            return to::CameraModel::Pinhole;
        case 1:
            return to::CameraModel::Fisheye;
        default:
            return to::CameraModel::Other;
        }
    }
    static std::array<double, 3> bearing(KeyFrame &kf, const cv::KeyPoint &k)
    {
        const Vector3f r = kf.mpCamera->unprojectEig(k.pt);
        return {r(0), r(1), r(2)};
    }
    static int left_count(KeyFrame &kf) { return kf.NLeft; }
};

} // namespace orb3

using Db2 = to::KeyFrameDatabase<orb2::KeyFrame, Frame>;
using Db3 = to::KeyFrameDatabase<orb3::KeyFrame, Frame, orb3::Access>;

// ---------------------------------------------------------------------------------------------
// A scene seen twice, and unrelated keyframes
// ---------------------------------------------------------------------------------------------

constexpr std::size_t kPoints = 80;
constexpr double kYaw = 3.0 * 3.14159265358979323846 / 180.0;

// The revisiting camera in the first camera's frame: 0.3 m right, 0.1 m ahead, turned by kYaw
// about its y axis. This is the `matched_T_query` a hint must find.
to::Pose revisit_in_first()
{
    const double c = std::cos(kYaw), s = std::sin(kYaw);
    return {c, 0, s, 0.3, 0, 1, 0, 0, -s, 0, c, 0.1, 0, 0, 0, 1};
}

// The first camera in the world (`Twc`): anywhere, turned 90 degrees, so that a pose or point
// handled in the wrong frame shows.
to::Pose first_Twc() { return {0, 0, 1, 5.0, 0, 1, 0, 2.0, -1, 0, 0, 1.0, 0, 0, 0, 1}; }

to::Pose compose(const to::Pose &a, const to::Pose &b)
{
    to::Pose out{};
    for (std::size_t r = 0; r < 4; ++r)
        for (std::size_t c = 0; c < 4; ++c)
            for (std::size_t k = 0; k < 4; ++k)
                out[4 * r + c] += a[4 * r + k] * b[4 * k + c];
    return out;
}

struct Rng {
    uint64_t state;
    double uniform()
    {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return double(state >> 11) / 9007199254740992.0;
    }
    uint8_t byte() { return uint8_t(uniform() * 256.0); }
};

bool project(const std::array<double, 3> &Xc, cv::Point2f &px)
{
    if (Xc[2] < 0.5)
        return false;
    px = cv::Point2f(float(kF * Xc[0] / Xc[2] + kCx), float(kF * Xc[1] / Xc[2] + kCy));
    return px.x >= 0 && px.x < 159 && px.y >= 0 && px.y < 119;
}

// What one keyframe sees, independent of the ORB-SLAM version.
struct Shot {
    unsigned long id = 0;
    double t = 0.0;
    cv::Mat image;
    std::vector<cv::KeyPoint> keys;
    cv::Mat descriptors; // N x 32 CV_8U
    to::Pose Twc{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    std::vector<std::optional<std::array<double, 3>>> world; // per keypoint
};

cv::Mat image_of(const std::vector<uint8_t> &px)
{
    return cv::Mat(int(kImgH), int(kImgW), CV_8UC1, const_cast<uint8_t *>(px.data())).clone();
}

struct Scene {
    std::vector<std::array<double, 3>> world; // in the first camera's frame
    std::vector<std::array<uint8_t, 32>> bytes;
    std::vector<cv::Point2f> first, second;
};

const Scene &scene()
{
    static const Scene s = [] {
        Scene out;
        Rng rng{2024};
        const to::Pose Tcw2 = to::inverse_rigid(revisit_in_first());
        while (out.world.size() < kPoints) {
            const double z = 3.0 + 5.0 * rng.uniform();
            const std::array<double, 3> X{(rng.uniform() - 0.5) * z,
                                          (rng.uniform() - 0.5) * 0.7 * z, z};
            cv::Point2f a, b;
            const bool seen = project(X, a) && project(to::transform_point(Tcw2, X), b);
            std::array<uint8_t, 32> d{};
            for (uint8_t &v : d)
                v = rng.byte();
            if (!seen)
                continue;
            out.world.push_back(X);
            out.bytes.push_back(d);
            out.first.push_back(a);
            out.second.push_back(b);
        }
        return out;
    }();
    return s;
}

// The scene from the first camera (`revisit` false, place image 0) or the second one (its
// keypoints in reverse order, the place image seen again). Every keypoint has its map point.
Shot scene_shot(unsigned long id, double t, bool revisit)
{
    const Scene &s = scene();
    Shot shot;
    shot.id = id;
    shot.t = t;
    shot.image =
        revisit ? image_of(revisit_pixels(places_pixels()[0], 99)) : image_of(places_pixels()[0]);
    shot.descriptors = cv::Mat(int(kPoints), 32, CV_8U);
    for (std::size_t k = 0; k < kPoints; ++k) {
        const std::size_t i = revisit ? kPoints - 1 - k : k;
        const cv::Point2f px = revisit ? s.second[i] : s.first[i];
        shot.keys.emplace_back(px, 31.f);
        std::copy(s.bytes[i].begin(), s.bytes[i].end(), shot.descriptors.ptr<uint8_t>(int(k)));
        shot.world.push_back(to::transform_point(first_Twc(), s.world[i]));
    }
    shot.Twc = revisit ? compose(first_Twc(), revisit_in_first()) : first_Twc();
    return shot;
}

// An unrelated keyframe at place image `place` (1..7), 2 m apart along x: random keypoints and
// descriptors, map points for every other keypoint.
Shot other_shot(unsigned long id, double t, uint32_t place)
{
    Shot shot;
    shot.id = id;
    shot.t = t;
    shot.image = image_of(places_pixels()[place]);
    shot.Twc[3] = 2.0 + 2.0 * place;
    Rng rng{7000 + place};
    shot.descriptors = cv::Mat(int(kPoints), 32, CV_8U);
    for (std::size_t k = 0; k < kPoints; ++k) {
        shot.keys.emplace_back(float(rng.uniform() * 159), float(rng.uniform() * 119), 31.f);
        for (int b = 0; b < 32; ++b)
            shot.descriptors.at<uint8_t>(int(k), b) = rng.byte();
        const std::array<double, 3> Xc{rng.uniform() - 0.5, rng.uniform() - 0.5,
                                       2.0 + rng.uniform()};
        if (k % 2 == 0)
            shot.world.push_back(to::transform_point(shot.Twc, Xc));
        else
            shot.world.push_back(std::nullopt);
    }
    return shot;
}

// Owns stand-in keyframes and map points of one ORB-SLAM version (stable addresses).
template <typename KeyFrame, typename MapPoint> struct World {
    std::deque<KeyFrame> keyframes;
    std::deque<MapPoint> points;

    KeyFrame *make(const Shot &shot, Map *map = nullptr)
    {
        KeyFrame &kf = keyframes.emplace_back();
        kf.mnId = shot.id;
        kf.mTimeStamp = shot.t;
        kf.mvKeysUn = shot.keys;
        kf.fx = float(kF);
        kf.fy = float(kF);
        kf.cx = float(kCx);
        kf.cy = float(kCy);
        kf.mDescriptors = shot.descriptors.clone();
        kf.mImGray = shot.image.clone();
        kf.Tcw = to::inverse_rigid(shot.Twc);
        kf.mpMap = map;
        for (const auto &X : shot.world) {
            if (!X) {
                kf.points.push_back(nullptr);
                continue;
            }
            MapPoint &mp = points.emplace_back();
            mp.xyz = *X;
            kf.points.push_back(&mp);
        }
        return &kf;
    }
};

using World2 = World<orb2::KeyFrame, orb2::MapPoint>;
using World3 = World<orb3::KeyFrame, orb3::MapPoint>;

Frame frame_of(uint32_t place)
{
    Frame f;
    f.mnId = 500 + place;
    f.mImGray = image_of(revisit_pixels(places_pixels()[place], 1234 + place));
    return f;
}

topoloc::LoopOptions test_options(uint32_t consistent = 1)
{
    topoloc::LoopOptions options = topoloc::default_loop_options();
    options.exclude_recent_ids = 5;
    options.exclude_recent_s = 0.0;
    options.consistent_keyframes = consistent;
    // A tight odometry gate: a hint passes only if the poses given as world_T_body agree with it.
    options.odometry_max_translation_m = 0.15;
    options.odometry_max_translation_per_m = 0.0;
    options.odometry_max_rotation_deg = 2.0;
    return options;
}

const to::Intrinsics kIntrinsics{kF, kF, kCx, kCy};

// Collects logged messages (the logger may be called from several threads).
struct Log {
    std::mutex mutex;
    std::vector<std::string> lines;
    std::function<void(const std::string &)> sink()
    {
        return [this](const std::string &line) {
            std::lock_guard<std::mutex> lock(mutex);
            lines.push_back(line);
        };
    }
    std::size_t count()
    {
        std::lock_guard<std::mutex> lock(mutex);
        return lines.size();
    }
};

to::Settings settings_with(Log &log, std::size_t relocalization = 5)
{
    to::Settings s;
    s.relocalization_candidates = relocalization;
    s.logger = log.sink();
    return s;
}

bool contains_text(const std::string &text, const std::string &part)
{
    return text.find(part) != std::string::npos;
}

// The hint's pose against the truth: translation error (m) and rotation error (rad).
template <typename Match> std::pair<double, double> pose_error(const Match &m)
{
    const to::Pose truth = revisit_in_first();
    const to::Pose &T = m.matched_T_query;
    double dt = 0, trace = 0;
    for (std::size_t r = 0; r < 3; ++r) {
        dt += (T[4 * r + 3] - truth[4 * r + 3]) * (T[4 * r + 3] - truth[4 * r + 3]);
        for (std::size_t c = 0; c < 3; ++c)
            trace += T[4 * r + c] * truth[4 * r + c]; // tr(T^T R)
    }
    return {std::sqrt(dt), std::acos(std::clamp((trace - 1.0) / 2.0, -1.0, 1.0))};
}

template <typename Match>
void check_revisit_hint(const std::optional<Match> &hint, const void *query, const void *matched)
{
    CHECK(hint.has_value());
    if (!hint)
        return;
    CHECK(hint->accepted && hint->gate == topoloc::Gate::Accepted);
    CHECK(hint->query == query && hint->matched == matched);
    CHECK(hint->has_pose && hint->scale_known);
    CHECK(hint->inliers >= 30);
    const auto [dt, dr] = pose_error(*hint);
    CHECK(dt < 0.05);
    CHECK(dr < 1.0 * 3.14159265358979323846 / 180.0);
    // query_T_matched is the inverse: their product is the identity.
    for (std::size_t r = 0; r < 4; ++r)
        for (std::size_t c = 0; c < 4; ++c) {
            double v = 0;
            for (std::size_t k = 0; k < 4; ++k)
                v += hint->query_T_matched[4 * r + k] * hint->matched_T_query[4 * k + c];
            CHECK(std::abs(v - (r == c ? 1.0 : 0.0)) < 1e-9);
        }
    for (std::size_t i = 0; i < 6; ++i)
        CHECK(hint->covariance[7 * i] > 0.0);
}

// Adds the scene keyframe (id 1, `kfs[0]`, at time `t0`) and unrelated keyframes of places 1..4
// (ids 2..5, `kfs[1..4]`, one second apart after it), all in `map`.
template <typename Db, typename W, typename KeyFrame>
void add_scene_and_others(Db &db, W &world, std::vector<KeyFrame *> &kfs, Map *map = nullptr,
                          double t0 = 0.0)
{
    kfs.push_back(world.make(scene_shot(1, t0, false), map));
    for (uint32_t p = 1; p <= 4; ++p)
        kfs.push_back(world.make(other_shot(1 + p, t0 + p, p), map));
    for (KeyFrame *kf : kfs)
        db.add(kf);
}

// The usual start of an ORB-SLAM2 test: a database whose settings log to `log` (at most
// `relocalization` relocalization candidates), holding the scene keyframe and four others
// (`kfs`, ids 1..5; see add_scene_and_others) of `world`. Tests bind the parts by name:
//   Orb2Scene scene;
//   auto &[log, db, world, kfs] = scene;
struct Orb2Scene {
    Log log;
    Db2 db;
    World2 world;
    std::vector<orb2::KeyFrame *> kfs;

    explicit Orb2Scene(const topoloc::LoopOptions &options = test_options(),
                       std::size_t relocalization = 5)
        : db(image_map(), kIntrinsics, options, settings_with(log, relocalization))
    {
        add_scene_and_others(db, world, kfs);
    }
};

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

TEST(orbslam2_detect_then_add_closes_the_loop)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    CHECK_EQ(db.size(), std::size_t{5});
    CHECK(db.last_error().empty());
    CHECK(!db.GetHint(kfs[0]).has_value()); // the first keyframe had nothing to match
    for (orb2::KeyFrame *kf : kfs)
        CHECK(kf->mImGray.empty()); // freed once added

    // LoopClosing::DetectLoop: query first, add afterwards.
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    const std::vector<orb2::KeyFrame *> found = db.DetectLoopCandidates(revisit, 0.9f);
    CHECK(found.size() == 1 && found[0] == kfs[0]);
    CHECK(db.contains(revisit));
    CHECK_EQ(db.size(), std::size_t{6});
    db.add(revisit); // a no-op now
    CHECK_EQ(db.size(), std::size_t{6});
    CHECK(db.last_error().empty());
    check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);
    // Asking again answers from the kept hint.
    CHECK(db.DetectLoopCandidates(revisit, 0.f) == found);
    CHECK_EQ(db.error_count(), std::size_t{0});
    CHECK_EQ(log.count(), std::size_t{0});
    CHECK(db.TakeConfirmed().empty());
}

TEST(orbslam2_add_without_detect_keeps_the_hint)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    db.add(revisit); // DetectLoop's early return: add only
    CHECK_EQ(db.size(), std::size_t{6});
    check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);
    CHECK(db.DetectLoopCandidates(revisit, 0.f) == std::vector<orb2::KeyFrame *>{kfs[0]});
}

TEST(orbslam3_loop_and_merge_candidates)
{
    for (const bool other_map : {false, true}) {
        Map first, second;
        Db3 db(image_map(), kIntrinsics, test_options());
        World3 world;
        std::vector<orb3::KeyFrame *> kfs;
        add_scene_and_others(db, world, kfs, &first);
        orb3::KeyFrame *revisit =
            world.make(scene_shot(10, 10.0, true), other_map ? &second : &first);
        std::vector<orb3::KeyFrame *> loop, merge;
        db.DetectNBestCandidates(revisit, loop, merge, 3);
        CHECK(db.last_error().empty());
        CHECK(loop.size() == (other_map ? 0u : 1u) && merge.size() == (other_map ? 1u : 0u));
        const std::vector<orb3::KeyFrame *> &hit = other_map ? merge : loop;
        CHECK(!hit.empty() && hit[0] == kfs[0]);
        db.add(revisit); // NewDetectCommonRegions adds after querying: a no-op
        CHECK_EQ(db.size(), std::size_t{6});
        check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);
        // The deprecated ORB-SLAM3 loop query keeps same-map candidates only.
        CHECK_EQ(db.DetectLoopCandidates(revisit, 0.f).size(),
                 other_map ? std::size_t{0} : std::size_t{1});
        // No candidates are asked for: none given.
        std::vector<orb3::KeyFrame *> loop0, merge0;
        db.DetectNBestCandidates(revisit, loop0, merge0, 0);
        CHECK(loop0.empty() && merge0.empty());
    }
}

TEST(orbslam3_relocalization_keeps_the_map)
{
    Map first, second;
    Db3 db(image_map(), kIntrinsics, test_options());
    World3 world;
    std::vector<orb3::KeyFrame *> kfs;
    kfs.push_back(world.make(scene_shot(1, 0.0, false), &first));
    for (uint32_t p = 1; p <= 4; ++p)
        kfs.push_back(world.make(other_shot(1 + p, double(p), p), p % 2 == 0 ? &second : &first));
    for (auto *kf : kfs)
        db.add(kf);
    Frame f = frame_of(2);
    const std::vector<orb3::KeyFrame *> in_second = db.DetectRelocalizationCandidates(&f, &second);
    CHECK(!in_second.empty() && in_second[0] == kfs[2]);
    for (auto *kf : in_second)
        CHECK(kf->mpMap == &second);
    const std::vector<orb3::KeyFrame *> in_first = db.DetectRelocalizationCandidates(&f, &first);
    CHECK(!in_first.empty());
    for (auto *kf : in_first)
        CHECK(kf->mpMap == &first);
    // clearMap drops one map's keyframes.
    db.clearMap(&second);
    CHECK_EQ(db.size(), std::size_t{3});
    CHECK(!db.contains(kfs[2]) && !db.contains(kfs[4]) && db.contains(kfs[1]));
    CHECK(db.DetectRelocalizationCandidates(&f, &second).empty());
    CHECK(db.last_error().empty());
}

TEST(relocalization_ranks_the_right_keyframe_first_and_erase_removes)
{
    Orb2Scene scene(test_options(), 3);
    auto &[log, db, world, kfs] = scene;
    for (uint32_t place = 0; place <= 4; ++place) {
        Frame f = frame_of(place);
        const std::vector<orb2::KeyFrame *> found = db.DetectRelocalizationCandidates(&f);
        CHECK(!found.empty() && found.size() <= 3);
        CHECK(!found.empty() && found[0] == kfs[place]);
        CHECK_EQ(std::set<orb2::KeyFrame *>(found.begin(), found.end()).size(), found.size());
    }
    Frame f2 = frame_of(2);
    db.erase(kfs[2]);
    CHECK(db.last_error().empty());
    CHECK_EQ(db.size(), std::size_t{4});
    CHECK(!db.contains(kfs[2]));
    std::vector<orb2::KeyFrame *> found = db.DetectRelocalizationCandidates(&f2);
    CHECK(!found.empty() && std::find(found.begin(), found.end(), kfs[2]) == found.end());
    // A culled keyframe is never a candidate, even before ORB-SLAM erases it.
    kfs[3]->mbBad = true;
    Frame f3 = frame_of(3);
    found = db.DetectRelocalizationCandidates(&f3);
    CHECK(!found.empty() && std::find(found.begin(), found.end(), kfs[3]) == found.end());
    kfs[3]->mbBad = false;
    // Erasing a keyframe never added is a no-op (as ORB-SLAM's own database) that frees its
    // image; erasing one twice is the host's mistake, reported.
    orb2::KeyFrame *never = world.make(other_shot(6, 9.0, 5));
    db.erase(never);
    CHECK(db.last_error().empty() && never->mImGray.empty());
    CHECK_EQ(log.count(), std::size_t{0});
    db.erase(kfs[2]);
    CHECK(contains_text(db.last_error(), "erase: keyframe 3 was erased already"));
    CHECK_EQ(db.size(), std::size_t{4});
    CHECK_EQ(log.count(), std::size_t{1});
    // An erased keyframe is no loop candidate either.
    db.erase(kfs[0]);
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    CHECK(db.DetectLoopCandidates(revisit, 0.f).empty());
    CHECK(db.last_error().empty());
    CHECK_EQ(db.size(), std::size_t{4});
}

// Runs one bad call: it must fail with a message naming `part`, log it, return no candidates
// and leave the database as it was.
struct BadCase {
    Db2 &db;
    Log &log;
    void expect(const std::string &name, const std::function<std::size_t()> &call,
                const std::string &part)
    {
        const std::size_t size = db.size(), errors = db.error_count(), logged = log.count();
        const std::size_t candidates = call();
        const std::string error = db.last_error();
        if (!contains_text(error, part))
            std::printf("    %s: error \"%s\"\n", name.c_str(), error.c_str());
        CHECK(contains_text(error, part));
        CHECK_EQ(candidates, std::size_t{0});
        CHECK_EQ(db.size(), size);
        CHECK_EQ(db.error_count(), errors + 1);
        CHECK_EQ(log.count(), logged + 1);
    }
    // The same for a call that returns nothing.
    void expect_done(const std::string &name, const std::function<void()> &call,
                     const std::string &part)
    {
        expect(
            name,
            [&] {
                call();
                return std::size_t{0};
            },
            part);
    }
    void expect_loop(const std::string &name, orb2::KeyFrame *kf, const std::string &part)
    {
        expect(
            name, [&] { return db.DetectLoopCandidates(kf, 0.f).size(); }, part);
        CHECK(kf == nullptr || !db.contains(kf));
    }
};

TEST(bad_inputs_are_reported_and_change_nothing)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    BadCase bad{db, log};

    bad.expect_loop("null keyframe", nullptr, "null keyframe");
    bad.expect_loop("duplicate id", world.make(other_shot(5, 9.0, 5)),
                    "another keyframe with this id");
    bad.expect_loop("id out of order", world.make(other_shot(0, 9.0, 5)), "ids must increase");
    bad.expect_loop("earlier timestamp", world.make(other_shot(6, 1.5, 5)), "earlier");

    orb2::KeyFrame *kf = world.make(other_shot(6, 9.0, 5));
    kf->Tcw[5] = std::numeric_limits<double>::quiet_NaN();
    bad.expect_loop("NaN pose", kf, "NaN");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->has_pose = false; // poses on all keyframes or none
    bad.expect_loop("missing pose", kf, "world_t_body");

    kf = world.make(other_shot(6, 9.0, 5));
    cv::resize(kf->mImGray, kf->mImGray, cv::Size(80, 60));
    bad.expect_loop("image size", kf, "the first keyframe's was 160x120");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mImGray = cv::Mat();
    bad.expect_loop("no image", kf, "empty");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mImGray = cv::Mat(int(kImgH), int(kImgW), CV_16UC1, cv::Scalar(100));
    bad.expect_loop("16-bit image", kf, "CV_8UC1");

    kf = world.make(other_shot(6, 9.0, 5));
    kf->mDescriptors.convertTo(kf->mDescriptors, CV_32F);
    bad.expect_loop("float descriptors", kf, "x 32 CV_8U");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mDescriptors = kf->mDescriptors.colRange(0, 31).clone();
    bad.expect_loop("31-byte descriptors", kf, "x 32 CV_8U");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mvKeysUn.pop_back();
    bad.expect_loop("descriptor count", kf, "79 x 32 CV_8U");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->points.pop_back();
    bad.expect_loop("map point count", kf, "79 map point matches for 80 keypoints");
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mvKeysUn[4].pt.x = std::numeric_limits<float>::infinity();
    bad.expect_loop("infinite keypoint", kf, "keypoint 4");

    // The same through add and DetectNBestCandidates.
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mDescriptors = cv::Mat();
    bad.expect_done(
        "add", [&] { db.add(kf); }, "x 32 CV_8U");
    bad.expect(
        "DetectNBestCandidates",
        [&] {
            std::vector<orb2::KeyFrame *> loop, merge;
            db.DetectNBestCandidates(kf, loop, merge, 3);
            return loop.size() + merge.size();
        },
        "x 32 CV_8U");

    // Relocalization of unusable frames, erase of an unknown keyframe.
    bad.expect(
        "null frame", [&] { return db.DetectRelocalizationCandidates(nullptr).size(); },
        "null frame");
    Frame small = frame_of(1);
    cv::resize(small.mImGray, small.mImGray, cv::Size(80, 60));
    bad.expect(
        "frame size", [&] { return db.DetectRelocalizationCandidates(&small).size(); },
        "frame image is 80x60");
    Frame flat;
    flat.mImGray = cv::Mat(int(kImgH), int(kImgW), CV_8UC1, cv::Scalar(128));
    bad.expect(
        "flat frame", [&] { return db.DetectRelocalizationCandidates(&flat).size(); },
        "DetectRelocalizationCandidates: ");
    bad.expect_done(
        "erase null", [&] { db.erase(nullptr); }, "null keyframe");
    bad.expect(
        "hint of unknown", [&] { return std::size_t(db.GetHint(kf).has_value()); },
        "not in the database");

    // A culled keyframe still queued for loop closing is skipped without an error.
    kf = world.make(other_shot(6, 9.0, 5));
    kf->mbBad = true;
    CHECK(db.DetectLoopCandidates(kf, 0.f).empty());
    db.add(kf);
    CHECK(db.last_error().empty() && !db.contains(kf) && db.size() == 5);

    // A logger that throws is contained.
    db.SetLogger([](const std::string &) { throw std::runtime_error("logger"); });
    CHECK(db.DetectLoopCandidates(nullptr, 0.f).empty());
    CHECK(contains_text(db.last_error(), "null keyframe"));
    db.SetLogger(log.sink());

    // Nothing above changed the database: the revisit still closes the loop, and succeeds.
    CHECK_EQ(db.size(), std::size_t{5});
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    CHECK(db.DetectLoopCandidates(revisit, 0.f) == std::vector<orb2::KeyFrame *>{kfs[0]});
    CHECK(db.last_error().empty());
    check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);
    Frame f = frame_of(3);
    const std::vector<orb2::KeyFrame *> found = db.DetectRelocalizationCandidates(&f);
    CHECK(!found.empty() && found[0] == kfs[3]);
}

TEST(clear_starts_afresh_and_refuses_earlier_keyframes)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    CHECK_EQ(db.DetectLoopCandidates(revisit, 0.f).size(), std::size_t{1});

    db.clear();
    CHECK(db.last_error().empty());
    CHECK_EQ(db.size(), std::size_t{0});
    CHECK(!db.contains(kfs[0]) && !db.contains(revisit));
    Frame f = frame_of(2);
    CHECK(db.DetectRelocalizationCandidates(&f).empty());
    CHECK(contains_text(db.last_error(), "no keyframe is held yet"));
    BadCase bad{db, log};
    bad.expect_loop("query of an earlier keyframe", revisit, "added before clear()");
    bad.expect_done(
        "add of an earlier keyframe", [&] { db.add(kfs[1]); }, "added before clear()");
    bad.expect_done(
        "erase of an earlier keyframe", [&] { db.erase(kfs[0]); }, "added before clear()");
    CHECK_EQ(db.size(), std::size_t{0});

    // ORB-SLAM restarts its ids after a reset: the fresh detector takes them.
    std::vector<orb2::KeyFrame *> again;
    add_scene_and_others(db, world, again);
    CHECK_EQ(db.size(), std::size_t{5});
    orb2::KeyFrame *revisit2 = world.make(scene_shot(10, 10.0, true));
    CHECK(db.DetectLoopCandidates(revisit2, 0.f) == std::vector<orb2::KeyFrame *>{again[0]});
    check_revisit_hint(db.GetHint(revisit2), revisit2, again[0]);
    const std::vector<orb2::KeyFrame *> found = db.DetectRelocalizationCandidates(&f);
    CHECK(!found.empty() && found[0] == again[2]);
}

TEST(a_completed_streak_confirms_earlier_keyframes_once)
{
    Orb2Scene scene(test_options(3));
    auto &[log, db, world, kfs] = scene;
    std::vector<orb2::KeyFrame *> streak;
    for (unsigned long id : {10ul, 11ul, 12ul})
        streak.push_back(world.make(scene_shot(id, double(id), true)));
    for (std::size_t i = 0; i < 2; ++i) {
        CHECK(db.DetectLoopCandidates(streak[i], 0.f).empty());
        const auto hint = db.GetHint(streak[i]);
        CHECK(hint && !hint->accepted && hint->gate == topoloc::Gate::Inconsistent);
        CHECK(db.TakeConfirmed().empty());
    }
    CHECK(db.DetectLoopCandidates(streak[2], 0.f) == std::vector<orb2::KeyFrame *>{kfs[0]});
    const std::vector<Db2::Match> confirmed = db.TakeConfirmed();
    CHECK_EQ(confirmed.size(), std::size_t{2});
    for (std::size_t i = 0; i < confirmed.size() && i < 2; ++i) {
        CHECK(confirmed[i].query == streak[i]);
        check_revisit_hint(std::optional<Db2::Match>(confirmed[i]), streak[i], kfs[0]);
        check_revisit_hint(db.GetHint(streak[i]), streak[i], kfs[0]); // the kept hint too
    }
    CHECK(db.TakeConfirmed().empty()); // taken once
}

TEST(tracking_and_loop_threads_share_the_database)
{
    Log log;
    Db2 db(image_map(), kIntrinsics, test_options(), settings_with(log));
    World2 world;
    std::vector<orb2::KeyFrame *> kfs;
    kfs.push_back(world.make(scene_shot(1, 0.0, false)));
    for (uint32_t p = 1; p <= 4; ++p)
        kfs.push_back(world.make(other_shot(1 + p, double(p), p)));
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    db.add(kfs[0]);
    db.add(kfs[1]);
    std::vector<orb2::KeyFrame *> found_loop;
    std::thread loop_thread([&] {
        for (std::size_t i : {2, 3, 4})
            db.add(kfs[i]);
        found_loop = db.DetectLoopCandidates(revisit, 0.f);
    });
    std::vector<std::vector<orb2::KeyFrame *>> relocalized;
    Frame f = frame_of(1);
    for (int i = 0; i < 6; ++i)
        relocalized.push_back(db.DetectRelocalizationCandidates(&f));
    loop_thread.join();
    CHECK(found_loop == std::vector<orb2::KeyFrame *>{kfs[0]});
    for (const auto &found : relocalized)
        CHECK(!found.empty() && found[0] == kfs[1]);
    CHECK_EQ(db.size(), std::size_t{6});
    CHECK_EQ(db.error_count(), std::size_t{0});
    CHECK_EQ(log.count(), std::size_t{0});
}

TEST(constructor_needs_a_map_with_a_describer)
{
    topoloc::MapBuilder builder("ext", "m", 4);
    (void)builder.add_place();
    const std::array<float, 4> d{1, 0, 0, 0};
    (void)builder.add_view(0, d.data(), d.size());
    const topoloc::Map plain = builder.build();
    CHECK_THROWS_STATUS((Db2{plain, kIntrinsics}), TOPOLOC_ERR_NO_DESCRIBER);
    topoloc::LoopOptions options = test_options();
    options.min_inliers = 3; // out of range (8..=10000)
    CHECK_THROWS_STATUS((Db2{image_map(), kIntrinsics, options}), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_THROWS_STATUS((Db2{image_map(), options}), TOPOLOC_ERR_INVALID_OPTION);
}

// `shot` moved into another world frame: 100 m along x and turned 90 degrees, as a new
// ORB-SLAM3 map's origin is unrelated to the lost one's.
Shot in_another_frame(Shot shot)
{
    const to::Pose origin{0, -1, 0, 100.0, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    shot.Twc = compose(origin, shot.Twc);
    for (auto &X : shot.world)
        if (X)
            X = to::transform_point(origin, *X);
    return shot;
}

// ORB-SLAM3 loses tracking and starts a new map, whose clock and world frame restart; the first
// keyframes of the new map see the scene of the map just lost. The default exclusion (30 ids,
// 10 s) and the odometry gate hid it while both maps shared one topoloc session; a new map now
// begins one, so the scene keyframe is a merge candidate at once, with the fitted pose. The
// intrinsics come from the keyframes.
TEST(orbslam3_a_new_map_finds_the_map_just_lost)
{
    for (const bool new_map : {false, true}) {
        Map first, second;
        topoloc::LoopOptions options = test_options();
        options.exclude_recent_ids = 30;
        options.exclude_recent_s = 10.0;
        Log log;
        Db3 db(image_map(), options, settings_with(log));
        World3 world;
        std::vector<orb3::KeyFrame *> kfs;
        add_scene_and_others(db, world, kfs, &first, 100.0);
        const Shot revisit_shot = scene_shot(6, new_map ? 0.0 : 105.0, true);
        orb3::KeyFrame *revisit = new_map ? world.make(in_another_frame(revisit_shot), &second)
                                          : world.make(revisit_shot, &first);
        std::vector<orb3::KeyFrame *> loop, merge;
        db.DetectNBestCandidates(revisit, loop, merge, 3);
        CHECK(db.last_error().empty());
        CHECK(loop.empty());
        if (!new_map) {
            CHECK(merge.empty()); // inside the exclusion window
            continue;
        }
        CHECK(merge == std::vector<orb3::KeyFrame *>{kfs[0]});
        check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);

        // Within the new map time must not go back.
        orb3::KeyFrame *earlier = world.make(other_shot(7, -1.0, 5), &second);
        db.add(earlier);
        CHECK(contains_text(db.last_error(), "earlier than the last one"));
        CHECK_EQ(db.size(), std::size_t{6});
        // A discarded map's keyframes are no candidates.
        first.bad = true;
        orb3::KeyFrame *again = world.make(in_another_frame(scene_shot(8, 1.0, true)), &second);
        std::vector<orb3::KeyFrame *> loop2, merge2;
        db.DetectNBestCandidates(again, loop2, merge2, 3);
        CHECK(loop2.empty() && merge2.empty());
        CHECK(db.last_error().empty());
        CHECK_EQ(log.count(), std::size_t{1});
    }
}

// ORB-SLAM3 saves its atlas and loads it in a later run: `Save` writes topoloc's keyframes
// beside it, `Load` opens them, the loaded keyframes come back without images (`Map::PostLoad`
// adds them) and are bound by id, and the new run's first keyframe, in a new map and world
// frame, merges with them.
TEST(a_saved_atlas_comes_back_and_merges)
{
    TempDir dir;
    const std::string path = (dir.path / "atlas.topoloc").string();
    Map saved_map, loaded_map, new_map;
    {
        Db3 db(image_map(), test_options());
        World3 world;
        std::vector<orb3::KeyFrame *> kfs;
        add_scene_and_others(db, world, kfs, &saved_map);
        CHECK(db.Save(path));
    }
    Log log;
    Db3 db(image_map(), test_options(), settings_with(log));
    CHECK(!db.Load(dir.path.string() + "/missing.topoloc"));
    CHECK(contains_text(db.last_error(), "Load: "));
    CHECK(db.Load(path));
    CHECK(db.last_error().empty());
    World3 world;
    std::vector<orb3::KeyFrame *> loaded;
    loaded.push_back(world.make(scene_shot(1, 0.0, false), &loaded_map));
    for (uint32_t p = 1; p <= 4; ++p)
        loaded.push_back(world.make(other_shot(1 + p, double(p), p), &loaded_map));
    for (orb3::KeyFrame *kf : loaded) {
        kf->mImGray.release(); // a loaded keyframe has no image
        db.add(kf);
    }
    CHECK(db.last_error().empty());
    CHECK_EQ(db.size(), std::size_t{5});
    CHECK(!db.Load(path)); // only into an empty database
    CHECK(contains_text(db.last_error(), "Load needs an empty database"));

    orb3::KeyFrame *revisit = world.make(in_another_frame(scene_shot(10, 0.5, true)), &new_map);
    std::vector<orb3::KeyFrame *> loop, merge;
    db.DetectNBestCandidates(revisit, loop, merge, 3);
    CHECK(loop.empty() && merge == std::vector<orb3::KeyFrame *>{loaded[0]});
    check_revisit_hint(db.GetHint(revisit), revisit, loaded[0]);
    // A keyframe without image that was not saved is still refused.
    orb3::KeyFrame *blank = world.make(other_shot(11, 1.0, 5), &new_map);
    blank->mImGray.release();
    db.add(blank);
    CHECK(contains_text(db.last_error(), "keyframe image is empty"));

    // After Shutdown every call is refused, nothing crashes.
    db.Shutdown();
    db.add(world.make(other_shot(12, 2.0, 6), &new_map));
    CHECK(contains_text(db.last_error(), "add: the database was shut down"));
    Frame f = frame_of(2);
    CHECK(db.DetectRelocalizationCandidates(&f).empty());
    CHECK(!db.Save(path));
}

// ORB-SLAM3 resets its active map (a new dataset, or tracking lost early) by clearMap and keeps
// using the same Map: its next keyframes, with a restarted clock, are taken.
TEST(orbslam3_a_reset_map_takes_a_restarted_clock)
{
    Map map;
    Db3 db(image_map(), test_options());
    World3 world;
    std::vector<orb3::KeyFrame *> kfs;
    add_scene_and_others(db, world, kfs, &map, 100.0);
    db.add(world.make(other_shot(6, 50.0, 5), &map)); // time going back without a reset
    CHECK(contains_text(db.last_error(), "earlier than the last one"));
    db.clearMap(&map);
    CHECK(db.last_error().empty());
    CHECK_EQ(db.size(), std::size_t{0});
    db.add(world.make(other_shot(7, 0.0, 5), &map));
    db.add(world.make(other_shot(8, 1.0, 6), &map));
    CHECK(db.last_error().empty());
    CHECK_EQ(db.size(), std::size_t{2});
    db.add(world.make(other_shot(9, 0.5, 7), &map)); // within the new run, time must not go back
    CHECK(contains_text(db.last_error(), "earlier than the last one"));
}

// ORB-SLAM3's fisheye keyframes keep raw fisheye pixels in mvKeysUn: the adapter projects
// their bearings to a pinhole, so the revisit's pose is right. A two-fisheye rig's keyframes
// have the second camera's descriptors and map points after the first's (NLeft rows of
// keypoints): they are used, not refused. Another camera model is refused.
TEST(orbslam3_fisheye_and_two_camera_keyframes)
{
    Map map;
    Db3 db(image_map(), test_options());
    World3 world;
    const auto to_fisheye = [](orb3::KeyFrame *kf) {
        kf->camera.type = 1;
        for (cv::KeyPoint &k : kf->mvKeysUn)
            k.pt = orb3::fisheye_pixel(k.pt);
        return kf;
    };
    std::vector<orb3::KeyFrame *> kfs{to_fisheye(world.make(scene_shot(1, 0.0, false), &map))};
    for (uint32_t p = 1; p <= 4; ++p)
        kfs.push_back(to_fisheye(world.make(other_shot(1 + p, double(p), p), &map)));
    for (orb3::KeyFrame *kf : kfs)
        db.add(kf);
    orb3::KeyFrame *revisit = to_fisheye(world.make(scene_shot(10, 10.0, true), &map));
    // A second camera's 7 keypoints follow the first's in the descriptors and map points.
    revisit->NLeft = int(kPoints);
    cv::Mat right(7, 32, CV_8U, cv::Scalar(5));
    cv::vconcat(revisit->mDescriptors, right, revisit->mDescriptors);
    revisit->points.resize(kPoints + 7, nullptr);
    std::vector<orb3::KeyFrame *> loop, merge;
    db.DetectNBestCandidates(revisit, loop, merge, 3);
    CHECK(db.last_error().empty());
    CHECK(loop == std::vector<orb3::KeyFrame *>{kfs[0]});
    check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);

    orb3::KeyFrame *other = world.make(other_shot(11, 11.0, 5), &map);
    other->camera.type = 2;
    db.add(other);
    CHECK(contains_text(db.last_error(), "neither pinhole nor Kannala-Brandt"));
    orb3::KeyFrame *short_rows = world.make(other_shot(12, 12.0, 6), &map);
    short_rows->NLeft = int(kPoints) - 1;
    db.add(short_rows);
    CHECK(contains_text(db.last_error(), "left_count (NLeft) is 79 for 80 keypoints"));
    CHECK_EQ(db.size(), std::size_t{6});
}

// As upstream, a keyframe connected to the query by covisibility is never its loop candidate
// (ORB-SLAM2 has no other guard against closing a loop with its own neighbours).
TEST(connected_keyframes_are_no_loop_candidates)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    orb2::KeyFrame *revisit = world.make(scene_shot(10, 10.0, true));
    revisit->connected = {kfs[0], kfs[1]};
    CHECK(db.DetectLoopCandidates(revisit, 0.f).empty());
    CHECK(db.last_error().empty());
    // topoloc's own verdict stays readable.
    check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);
}

// A keyframe whose intrinsics are not the run's is refused (ORB-SLAM3 replaces the settings
// file's Camera1.fx.. when it rectifies or resizes); a culled keyframe is skipped and its image
// freed; a monocular map turns the metric odometry gate off.
TEST(intrinsics_culled_keyframes_and_monocular_maps)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    orb2::KeyFrame *resized = world.make(other_shot(6, 6.0, 5));
    resized->fx = float(2 * kF);
    db.add(resized);
    CHECK(contains_text(db.last_error(), "keyframe 6 has intrinsics fx 300"));
    CHECK(contains_text(db.last_error(), "not the run's 150"));
    CHECK(!db.contains(resized) && !resized->mImGray.empty());
    orb2::KeyFrame *culled = world.make(other_shot(7, 7.0, 6));
    culled->mbBad = true;
    db.add(culled);
    CHECK(db.last_error().empty() && !db.contains(culled) && culled->mImGray.empty());

    // The revisit 1 m off in the odometry: the test's tight gate (0.15 m) refuses it, unless
    // the map is monocular (its units are not metres).
    for (const bool monocular : {false, true}) {
        to::Settings settings;
        settings.monocular = monocular;
        Db2 mono(image_map(), test_options(), settings);
        World2 w;
        mono.add(w.make(scene_shot(1, 0.0, false)));
        for (uint32_t p = 1; p <= 4; ++p)
            mono.add(w.make(other_shot(1 + p, double(p), p)));
        Shot shot = scene_shot(10, 10.0, true);
        shot.Twc[3] += 1.0;
        const std::size_t found = mono.DetectLoopCandidates(w.make(shot), 0.f).size();
        CHECK_EQ(found, monocular ? std::size_t{1} : std::size_t{0});
    }
}

TEST(keyframes_with_many_keypoints_give_those_with_map_points_first)
{
    Orb2Scene scene;
    auto &[log, db, world, kfs] = scene;
    // ORB-SLAM3's monocular initialisation: about 10,000 keypoints per keyframe, over topoloc's
    // bound. Here the revisit's 80 scene keypoints (each with its map point) come after 5,000
    // stronger ones without map points: keeping the first or the strongest would lose the loop.
    Shot shot = scene_shot(10, 10.0, true);
    Rng rng{99};
    std::vector<cv::KeyPoint> unmapped;
    cv::Mat unmapped_rows(int(to::kMaxKeypoints), 32, CV_8U);
    for (std::size_t k = 0; k < to::kMaxKeypoints; ++k) {
        unmapped.emplace_back(float(rng.uniform() * 159), float(rng.uniform() * 119), 31.f, -1.f,
                              100.f);
        for (int b = 0; b < 32; ++b)
            unmapped_rows.at<uint8_t>(int(k), b) = rng.byte();
    }
    shot.keys.insert(shot.keys.begin(), unmapped.begin(), unmapped.end());
    cv::vconcat(unmapped_rows, shot.descriptors, shot.descriptors);
    shot.world.insert(shot.world.begin(), to::kMaxKeypoints, std::nullopt);
    orb2::KeyFrame *revisit = world.make(shot);
    CHECK(db.DetectLoopCandidates(revisit, 0.f) == std::vector<orb2::KeyFrame *>{kfs[0]});
    CHECK(db.last_error().empty());
    check_revisit_hint(db.GetHint(revisit), revisit, kfs[0]);

    for (const std::size_t bad : {std::size_t{0}, to::kMaxKeypoints + 1}) {
        to::Settings settings;
        settings.max_keypoints = bad;
        bool threw = false;
        try {
            Db2 refused(image_map(), test_options(), settings);
        } catch (const topoloc::Error &e) {
            threw = contains_text(e.what(), "max_keypoints");
        }
        CHECK(threw);
    }
}

} // namespace

int main() { return run_all_tests(); }
