// ORB-SLAM3's keyframe database, answered by topoloc (see topoloc_orbslam.hpp). The interface
// is C++11, as the rest of ORB-SLAM3; src/KeyFrameDatabase.cc is compiled as C++17.
#ifndef KEYFRAMEDATABASE_H
#define KEYFRAMEDATABASE_H

#include <memory>
#include <string>
#include <vector>

#include "KeyFrame.h"
#include "Frame.h"
#include "ORBVocabulary.h"
#include "Map.h"

namespace ORB_SLAM3
{

class KeyFrame;
class Frame;
class Map;

class KeyFrameDatabase
{
public:
    // Reads Topoloc.map, Topoloc.monocular, Topoloc.max_keypoints and Topoloc.trace from the
    // settings file.
    explicit KeyFrameDatabase(const std::string &strSettingsFile);
    ~KeyFrameDatabase();

    void add(KeyFrame* pKF);
    void erase(KeyFrame* pKF);
    void clear();
    void clearMap(Map* pMap);
    std::vector<KeyFrame*> DetectLoopCandidates(KeyFrame* pKF, float minScore);
    void DetectNBestCandidates(KeyFrame* pKF, std::vector<KeyFrame*>& vpLoopCand,
                               std::vector<KeyFrame*>& vpMergeCand, int nNumCandidates);
    std::vector<KeyFrame*> DetectRelocalizationCandidates(Frame* F, Map* pMap);
    bool Save(const std::string &path);  // beside a saved atlas
    bool Load(const std::string &path);  // before Atlas::PostLoad adds the loaded keyframes
    void Shutdown();                     // once the loop closing thread has finished

private:
    struct Impl;
    std::unique_ptr<Impl> mpImpl;
};

} // namespace ORB_SLAM3

#endif
