// topoloc's loop detector inside VINS-Fusion's loop_fusion: the functions that the edits of
// topoloc's cpp-examples/vins/integrate/apply.py call from pose_graph.cpp and
// pose_graph_node.cpp, in place of the DBoW2 database and KeyFrame::findConnection.
//
// Part of topoloc (MIT OR Apache-2.0); it contains no VINS-Fusion code. Built into a fork of
// loop_fusion, which stays GPL-3.0 as a whole.
#pragma once

#include "topoloc/vins/topoloc_vins.hpp"

#include <Eigen/Dense>

#include <string>

class PoseGraph;
class KeyFrame;

/// Friend of `PoseGraph` (apply.py declares it there): reads and writes the members that
/// upstream's `detectLoop`, `findConnection` and the loop branch of `addKeyFrame` touch.
/// Thread safety: as upstream's, every call but `record` runs under the node's `m_process`;
/// `record` takes `m_keyframelist` and `m_optimize_buf` as upstream does.
struct TopolocLoop {
    /// Makes the detector from the topoloc map at `map_path` (the config's `topoloc_map`),
    /// with VINS's virtual pinhole (focal 460, the image centre `COL / 2`, `ROW / 2`) for the
    /// normalized coordinates. Exits the node with a message naming what to set when the path
    /// is empty or the map cannot be loaded.
    static void load(PoseGraph &graph, const std::string &map_path);

    /// `detectLoop` / `addKeyFrameIntoVoc`: adds `kf` (its image, VIO and origin poses, the
    /// window's points with their BRIEF descriptors, the extra FAST corners) and returns the old
    /// index of an accepted loop, or -1 (errors are logged through ROS_WARN). Releases the
    /// keyframe image afterwards unless `save_image` (DEBUG_IMAGE) keeps it, as upstream does.
    static int detect(PoseGraph &graph, KeyFrame *kf);

    /// `cur->findConnection(old_kf)`: writes the loop's `has_loop`, `loop_index` and
    /// `loop_info` on `cur` (not yet in the keyframe list); false if there is no loop with
    /// `old_index`.
    static bool connect(PoseGraph &graph, KeyFrame *cur, int old_index);

    /// After the loop branch: records the current loop and those topoloc confirmed on earlier
    /// keyframes, lowers `earliest_loop_index` to the oldest loop and queues one optimisation
    /// (`LoopDetector::pose_graph_update`).
    static void record(PoseGraph &graph, KeyFrame *cur, int loop_index);

    /// `extrinsic_callback`: the camera extrinsics VINS estimated (`tic`, `qic`).
    static void set_extrinsics(PoseGraph &graph, const Eigen::Vector3d &tic,
                               const Eigen::Matrix3d &qic);
};
