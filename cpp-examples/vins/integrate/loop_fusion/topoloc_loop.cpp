// See topoloc_loop.h. Part of topoloc (MIT OR Apache-2.0); no VINS-Fusion code.
#include "topoloc_loop.h"

#include "pose_graph.h"

#include <boost/dynamic_bitset.hpp>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <memory>
#include <mutex>
#include <vector>

namespace {

/// VINS's virtual focal length for normalized coordinates (keyframe.cpp's FOCAL_LENGTH).
constexpr double kVinsFocalLength = 460.0;

/// A 256-bit BRIEF descriptor as topoloc's 32 bytes; false for another length.
bool to_descriptor(const boost::dynamic_bitset<> &bits, topoloc_vins::Descriptor &out)
{
    if (bits.size() != out.size() * 8)
        return false;
    std::vector<boost::dynamic_bitset<>::block_type> blocks;
    boost::to_block_range(bits, std::back_inserter(blocks));
    std::memcpy(out.data(), blocks.data(), out.size());
    return true;
}

/// Every descriptor of `bits`; empty when one has another length than 256 bits (the keyframe
/// is then refused by the adapter's length check, with a log line).
std::vector<topoloc_vins::Descriptor> to_descriptors(const std::vector<BRIEF::bitset> &bits)
{
    std::vector<topoloc_vins::Descriptor> out(bits.size());
    for (std::size_t i = 0; i < bits.size(); ++i) {
        if (!to_descriptor(bits[i], out[i]))
            return {};
    }
    return out;
}

} // namespace

void TopolocLoop::load(PoseGraph &graph, const std::string &map_path)
{
    if (map_path.empty()) {
        std::fprintf(stderr, "loop_fusion: set topoloc_map in the config file to a map built by "
                             "`topoloc build-map` from images of another run\n");
        std::exit(1);
    }
    try {
        topoloc_vins::Config config;
        config.fx = config.fy = kVinsFocalLength;
        config.cx = COL / 2.0;
        config.cy = ROW / 2.0;
        graph.loops =
            std::make_unique<topoloc_vins::LoopDetector>(topoloc::Map::load(map_path), config);
        graph.loops->set_logger(
            [](const std::string &message) { ROS_WARN("%s", message.c_str()); });
    } catch (const std::exception &e) {
        std::fprintf(stderr, "loop_fusion: cannot use topoloc map %s: %s\n", map_path.c_str(),
                     e.what());
        std::exit(1);
    }
}

int TopolocLoop::detect(PoseGraph &graph, KeyFrame *kf)
{
    topoloc_vins::KeyFrame k;
    k.index = kf->index;
    k.time_stamp = kf->time_stamp;
    k.sequence = kf->sequence;
    k.image = kf->image;
    k.vio_T_w_i = kf->vio_T_w_i;
    k.vio_R_w_i = kf->vio_R_w_i;
    k.origin_vio_T = kf->origin_vio_T;
    k.origin_vio_R = kf->origin_vio_R;
    k.point_3d = kf->point_3d;
    k.point_2d_norm = kf->point_2d_norm;
    k.window_descriptors = to_descriptors(kf->window_brief_descriptors);
    k.keypoints_norm.reserve(kf->keypoints_norm.size());
    for (const cv::KeyPoint &p : kf->keypoints_norm)
        k.keypoints_norm.push_back(p.pt);
    k.descriptors = to_descriptors(kf->brief_descriptors);
    const int loop_index = graph.loops->detectLoop(k, kf->index);
    if (!DEBUG_IMAGE)
        kf->image.release();
    return loop_index;
}

bool TopolocLoop::connect(PoseGraph &graph, KeyFrame *cur, int old_index)
{
    topoloc_vins::LoopInfo info;
    if (!graph.loops->findConnection(cur->index, old_index, info))
        return false;
    cur->has_loop = true;
    cur->loop_index = old_index;
    cur->loop_info = info.loop_info();
    return true;
}

void TopolocLoop::record(PoseGraph &graph, KeyFrame *cur, int loop_index)
{
    const topoloc_vins::PoseGraphUpdate update =
        graph.loops->pose_graph_update(cur->index, loop_index, graph.earliest_loop_index);
    if (update.loops.empty())
        return;
    {
        std::lock_guard<std::mutex> lock(graph.m_keyframelist);
        for (const topoloc_vins::LoopInfo &info : update.loops) {
            KeyFrame *kf = info.cur_index == cur->index ? cur : graph.getKeyFrame(info.cur_index);
            if (kf == nullptr) {
                ROS_WARN("topoloc: keyframe %d of a confirmed loop is gone", info.cur_index);
                continue;
            }
            kf->has_loop = true;
            kf->loop_index = info.old_index;
            kf->loop_info = info.loop_info();
            std::printf("[topoloc-bench] loop %d %d\n", info.cur_index, info.old_index);
        }
    }
    graph.earliest_loop_index = update.earliest_loop_index;
    if (update.optimize_index >= 0) {
        std::lock_guard<std::mutex> lock(graph.m_optimize_buf);
        graph.optimize_buf.push(update.optimize_index);
    }
}

void TopolocLoop::set_extrinsics(PoseGraph &graph, const Eigen::Vector3d &tic,
                                 const Eigen::Matrix3d &qic)
{
    if (graph.loops)
        graph.loops->set_extrinsics(tic, qic);
}
