// Compiled as C++17 (see CMakeLists.txt).
#include "KeyFrameDatabase.h"

#include "Frame.h"
#include "KeyFrame.h"
#include "Map.h"
#include "MapPoint.h"

#include "topoloc_orbslam.hpp"

#include <cstdlib>
#include <iostream>

namespace ORB_SLAM3
{

// ORB-SLAM3 keeps poses as Sophus::SE3f and positions as Eigen::Vector3f, and has several maps.
struct TopolocAccess : topoloc_orbslam::DefaultAccess<KeyFrame, Frame>
{
    static std::optional<topoloc_orbslam::Pose> camera_from_world(KeyFrame &kf)
    {
        return topoloc_orbslam::pose_from_matrix(kf.GetPose().matrix());
    }
    static bool world_position(MapPoint *mp, std::array<double, 3> &out)
    {
        if(mp == nullptr || mp->isBad())
            return false;
        const Eigen::Vector3f p = mp->GetWorldPos();
        out = {p(0), p(1), p(2)};
        return true;
    }
    static const void *map_of(KeyFrame &kf) { return kf.GetMap(); }
    static bool map_is_bad(KeyFrame &kf) { return kf.GetMap() != nullptr && kf.GetMap()->IsBad(); }
    // Kannala-Brandt keyframes keep raw fisheye pixels in mvKeysUn; a stereo fisheye rig puts
    // the right camera's descriptors and map points after the left's (NLeft rows of keypoints).
    static topoloc_orbslam::CameraModel camera_model(KeyFrame &kf)
    {
        switch(kf.mpCamera->GetType())
        {
        case GeometricCamera::CAM_PINHOLE: return topoloc_orbslam::CameraModel::Pinhole;
        case GeometricCamera::CAM_FISHEYE: return topoloc_orbslam::CameraModel::Fisheye;
        default: return topoloc_orbslam::CameraModel::Other;
        }
    }
    static std::array<double, 3> bearing(KeyFrame &kf, const cv::KeyPoint &k)
    {
        const Eigen::Vector3f r = kf.mpCamera->unprojectEig(k.pt);
        return {r(0), r(1), r(2)};
    }
    static int left_count(KeyFrame &kf) { return kf.NLeft; }
};

using Database = topoloc_orbslam::KeyFrameDatabase<KeyFrame, Frame, TopolocAccess>;

struct KeyFrameDatabase::Impl
{
    std::unique_ptr<Database> db;
    bool trace = false;  // Topoloc.trace: one line per keyframe on stderr
};

// "topoloc-trace <keyframe id> <loop candidates> <merge candidates>", then, when topoloc verified
// a match, "<gate> <inliers> <matched id>" (gate: topoloc_gate, 0 = accepted).
static void Trace(Database &db, KeyFrame *pKF, std::size_t loops, std::size_t merges)
{
    const std::optional<topoloc_orbslam::LoopMatch<KeyFrame>> hint = db.GetHint(pKF);
    std::cerr << "topoloc-trace " << pKF->mnId << ' ' << loops << ' ' << merges;
    if(hint)
        std::cerr << ' ' << static_cast<unsigned>(hint->gate) << ' ' << hint->inliers << ' ' << hint->matched_id;
    std::cerr << std::endl;
}

static std::unique_ptr<Database> OpenDatabase(const std::string &strSettingsFile)
{
    cv::FileStorage fs(strSettingsFile, cv::FileStorage::READ);
    std::string mapFile;
    fs["Topoloc.map"] >> mapFile;
    topoloc::LoopOptions options = topoloc::default_loop_options();
    options.consistent_keyframes = 1;  // LoopClosing checks consistency itself
    topoloc_orbslam::Settings settings;
    settings.monocular = int(fs["Topoloc.monocular"]) != 0;
    if(!fs["Topoloc.max_keypoints"].empty())
        settings.max_keypoints = static_cast<std::size_t>(int(fs["Topoloc.max_keypoints"]));
    settings.logger = [](const std::string &message) { std::cerr << "topoloc: " << message << std::endl; };
    return std::make_unique<Database>(topoloc::Map::load(mapFile), options, settings);
}

KeyFrameDatabase::KeyFrameDatabase(const std::string &strSettingsFile) : mpImpl(new Impl)
{
    try
    {
        mpImpl->db = OpenDatabase(strSettingsFile);
        cv::FileStorage fs(strSettingsFile, cv::FileStorage::READ);
        mpImpl->trace = int(fs["Topoloc.trace"]) != 0;
    }
    catch(const std::exception &e)
    {
        std::cerr << "Cannot open the topoloc database: " << e.what() << std::endl;
        std::exit(-1);
    }
}

KeyFrameDatabase::~KeyFrameDatabase() = default;

void KeyFrameDatabase::add(KeyFrame *pKF) { mpImpl->db->add(pKF); }
void KeyFrameDatabase::erase(KeyFrame *pKF) { mpImpl->db->erase(pKF); }
void KeyFrameDatabase::clear() { mpImpl->db->clear(); }
void KeyFrameDatabase::clearMap(Map *pMap) { mpImpl->db->clearMap(pMap); }

std::vector<KeyFrame*> KeyFrameDatabase::DetectLoopCandidates(KeyFrame *pKF, float minScore)
{
    return mpImpl->db->DetectLoopCandidates(pKF, minScore);
}

void KeyFrameDatabase::DetectNBestCandidates(KeyFrame *pKF, std::vector<KeyFrame*> &vpLoopCand,
                                             std::vector<KeyFrame*> &vpMergeCand, int nNumCandidates)
{
    mpImpl->db->DetectNBestCandidates(pKF, vpLoopCand, vpMergeCand, nNumCandidates);
    if(mpImpl->trace)
        Trace(*mpImpl->db, pKF, vpLoopCand.size(), vpMergeCand.size());
}

std::vector<KeyFrame*> KeyFrameDatabase::DetectRelocalizationCandidates(Frame *F, Map *pMap)
{
    return mpImpl->db->DetectRelocalizationCandidates(F, pMap);
}

bool KeyFrameDatabase::Save(const std::string &path) { return mpImpl->db->Save(path); }
bool KeyFrameDatabase::Load(const std::string &path) { return mpImpl->db->Load(path); }
void KeyFrameDatabase::Shutdown() { mpImpl->db->Shutdown(); }

} // namespace ORB_SLAM3
