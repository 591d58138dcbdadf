// Trains a BRIEF bag-of-words vocabulary in the binary format VINS-Fusion's loop_fusion loads
// (support_files/brief_k10L6.bin, read by TemplatedVocabulary::loadBin through
// ThirdParty/VocabularyBinary.cpp), for the stock baseline: our mirror lacks brief_k10L6.bin.
// Images are described as loop_fusion describes a keyframe (KeyFrame::computeBRIEFPoint): FAST
// corners (threshold 20, non-maximum suppression), then DVision::BRIEF with the test pairs of
// support_files/brief_pattern.yml (256 bits). The tree is DBoW2's k-means++ tree with
// brief_k10L6.bin's parameters: k 10, L 6, TF-IDF weights, L1 scoring. After writing OUT.bin it
// loads it back with the upstream loader and requires, for a few training images, the same BoW
// vectors from the trained vocabulary, the reloaded one and a copy of it (loop_fusion's database
// keeps a copy), and the same word descriptors and weights.
//
//   train_brief_vocabulary [--seed N] PATTERN_YML OUT.bin IMAGE_OR_DIR...
//
// A DIR gives its image files (.png .jpg .jpeg .pgm .bmp .tif .tiff, any case), in name order; a
// file is used as given. Images are read grey; unreadable ones and those without a corner are
// skipped with a message. --seed: the k-means++ seed (default 1; the same seed, images and libc
// give the same file). Prints the images, descriptors, words, nodes, seconds and file size.
// Exit status 0, or 1 with a message on any error (bad arguments, no descriptor, a write or
// round-trip failure).
//
// VINS-Fusion is GPL-3.0: this file contains none of its code. It is compiled together with the
// upstream sources at build time, and only calls and subclasses them (build_vocabulary.sh):
//   T=$UP/loop_fusion/src/ThirdParty   # UP: a VINS-Fusion checkout, unmodified
//   g++ -std=c++17 -O2 -I"$T" $(pkg-config --cflags opencv4) -include opencv2/imgproc/types_c.h
//       train_brief_vocabulary.cpp "$T"/DBoW/{BowVector,FBrief,FeatureVector,ScoringObject}.cpp
//       "$T"/DUtils/{Random,Timestamp}.cpp "$T"/DVision/BRIEF.cpp "$T"/VocabularyBinary.cpp
//       $(pkg-config --libs opencv4) -o train_brief_vocabulary        (one command)
// (-include: DVision/BRIEF.cpp line 53 uses OpenCV's C constant CV_RGB2GRAY, which OpenCV 4
// declares only in opencv2/imgproc/types_c.h.)
#include "DBoW/BowVector.h"
#include "DBoW/FBrief.h"
#include "DBoW/TemplatedVocabulary.h"
#include "DUtils/Random.h"
#include "DVision/BRIEF.h"
#include "VocabularyBinary.hpp"

#include <boost/dynamic_bitset.hpp>
#include <opencv2/core/persistence.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

using Descriptor = DBoW2::FBrief::TDescriptor;

constexpr int kBranching = 10;     // k of brief_k10L6.bin
constexpr int kLevels = 6;         // L of brief_k10L6.bin
constexpr int kFastThreshold = 20; // loop_fusion's KeyFrame::computeBRIEFPoint
constexpr std::size_t kDescriptorBits = 256;
constexpr std::size_t kDescriptorBlocks =
    sizeof(VINSLoop::Node::descriptor) / sizeof(VINSLoop::Node::descriptor[0]);
constexpr int kRoundTripImages = 5;

static_assert(Descriptor::bits_per_block == 64 && sizeof(Descriptor::block_type) == 8,
              "loop_fusion's binary vocabulary stores descriptors as 64-bit blocks");
static_assert(kDescriptorBlocks * 64 == kDescriptorBits, "VINSLoop::Node holds 4 x 64 bits");

/// DBoW2's BRIEF vocabulary, with the writer of loop_fusion's binary format that upstream lacks:
/// the inverse of TemplatedVocabulary::loadBin. Constructors are upstream's (parameters, or a
/// binary file to load).
class BriefVocabulary : public DBoW2::TemplatedVocabulary<Descriptor, DBoW2::FBrief> {
public:
    using TemplatedVocabulary::TemplatedVocabulary;

    /// Number of tree nodes, the root excluded (the nodes the binary file stores).
    std::size_t nodeCount() const { return m_nodes.empty() ? 0 : m_nodes.size() - 1; }

    /// Writes the vocabulary as VINSLoop::Vocabulary::serialize does: the header, nodes 1..N in
    /// id order (so each parent gets its children back in training order) and the words.
    void saveBin(const std::string &path) const
    {
        if (m_nodes.size() < 2 || m_words.empty())
            throw std::runtime_error("the vocabulary is empty: nothing to write");
        VINSLoop::Vocabulary out;
        out.k = m_k;
        out.L = m_L;
        out.scoringType = m_scoring;
        out.weightingType = m_weighting;
        out.nNodes = checkedInt32(nodeCount(), "node count");
        out.nWords = checkedInt32(m_words.size(), "word count");
        out.nodes = new VINSLoop::Node[out.nNodes]; // freed by ~Vocabulary
        out.words = new VINSLoop::Word[out.nWords];

        for (std::size_t id = 1; id < m_nodes.size(); ++id) {
            const Node &node = m_nodes[id];
            if (node.id != id || node.parent >= id)
                throw std::runtime_error("node " + std::to_string(id) + " is out of order");
            if (node.descriptor.size() != kDescriptorBits ||
                node.descriptor.num_blocks() != kDescriptorBlocks)
                throw std::runtime_error("node " + std::to_string(id) + " has a " +
                                         std::to_string(node.descriptor.size()) +
                                         "-bit descriptor, not 256 bits");
            VINSLoop::Node &written = out.nodes[id - 1];
            written.nodeId = static_cast<std::int32_t>(node.id);
            written.parentId = static_cast<std::int32_t>(node.parent);
            written.weight = node.weight;
            boost::to_block_range(node.descriptor, std::begin(written.descriptor));
        }
        for (std::size_t wid = 0; wid < m_words.size(); ++wid) {
            if (m_words[wid]->word_id != wid)
                throw std::runtime_error("word " + std::to_string(wid) + " is out of order");
            out.words[wid].nodeId = static_cast<std::int32_t>(m_words[wid]->id);
            out.words[wid].wordId = static_cast<std::int32_t>(wid);
        }

        std::ofstream file(path, std::ios::binary | std::ios::trunc);
        if (!file)
            throw std::runtime_error("cannot open " + path + " for writing");
        out.serialize(file);
        file.close();
        if (!file)
            throw std::runtime_error("writing " + path + " failed");
    }

private:
    static std::int32_t checkedInt32(std::size_t value, const char *what)
    {
        if (value > static_cast<std::size_t>(INT32_MAX))
            throw std::runtime_error(std::string(what) + " does not fit the binary format");
        return static_cast<std::int32_t>(value);
    }
};

/// A BRIEF extractor with the test pairs of a pattern file (x1, y1, x2, y2 sequences, as
/// support_files/brief_pattern.yml), describing images as loop_fusion describes keyframes.
class KeyframeDescriber {
public:
    explicit KeyframeDescriber(const std::string &pattern_path)
    {
        cv::FileStorage pattern;
        try {
            pattern.open(pattern_path, cv::FileStorage::READ);
        } catch (const cv::Exception &e) {
            throw std::runtime_error("cannot parse BRIEF pattern " + pattern_path + ": " +
                                     e.what());
        }
        if (!pattern.isOpened())
            throw std::runtime_error("cannot open BRIEF pattern " + pattern_path);
        std::vector<int> x1, y1, x2, y2;
        pattern["x1"] >> x1;
        pattern["y1"] >> y1;
        pattern["x2"] >> x2;
        pattern["y2"] >> y2;
        if (x1.size() != kDescriptorBits || y1.size() != kDescriptorBits ||
            x2.size() != kDescriptorBits || y2.size() != kDescriptorBits)
            throw std::runtime_error("BRIEF pattern " + pattern_path +
                                     " must hold 256 values in each of x1, y1, x2, y2");
        brief_.importPairs(x1, y1, x2, y2);
    }

    /// FAST corners of a grey image and their BRIEF descriptors (smoothed by BRIEF::compute).
    std::vector<Descriptor> describe(const cv::Mat &grey) const
    {
        std::vector<cv::KeyPoint> corners;
        cv::FAST(grey, corners, kFastThreshold, true);
        std::vector<Descriptor> descriptors;
        brief_.compute(grey, corners, descriptors);
        return descriptors;
    }

private:
    DVision::BRIEF brief_;
};

bool isImageName(const fs::path &path)
{
    std::string ext = path.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    for (const char *known : {".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff"})
        if (ext == known)
            return true;
    return false;
}

/// The image files an argument names: a directory's image files in name order, or the argument.
std::vector<std::string> imagesOf(const std::string &argument)
{
    std::error_code error;
    if (!fs::is_directory(argument, error))
        return {argument};
    std::vector<std::string> files;
    for (const fs::directory_entry &entry : fs::directory_iterator(argument))
        if (entry.is_regular_file() && isImageName(entry.path()))
            files.push_back(entry.path().string());
    std::sort(files.begin(), files.end());
    if (files.empty())
        std::cerr << "train_brief_vocabulary: no image file in " << argument << "\n";
    return files;
}

double secondsSince(std::chrono::steady_clock::time_point start)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// Checks the file against the vocabulary it was written from: header, words, and the BoW vectors
/// of a few training images, from the reloaded vocabulary and from a copy of it. Returns the
/// number of images compared; throws on the first difference.
int checkRoundTrip(const BriefVocabulary &trained, const std::string &path,
                   const std::vector<std::vector<Descriptor>> &training)
{
    const BriefVocabulary reloaded(path); // upstream's loadBin
    BriefVocabulary copied;
    copied = reloaded; // as TemplatedDatabase::setVocabulary copies it (word ids rebuilt)
    const std::vector<const BriefVocabulary *> loaded = {&reloaded, &copied};
    for (const BriefVocabulary *other : loaded) {
        if (other->getBranchingFactor() != trained.getBranchingFactor() ||
            other->getDepthLevels() != trained.getDepthLevels() ||
            other->getWeightingType() != trained.getWeightingType() ||
            other->getScoringType() != trained.getScoringType() ||
            other->size() != trained.size() || other->nodeCount() != trained.nodeCount())
            throw std::runtime_error("reloaded header or sizes differ");
        for (DBoW2::WordId wid = 0; wid < trained.size(); ++wid)
            if (other->getWord(wid) != trained.getWord(wid) ||
                other->getWordWeight(wid) != trained.getWordWeight(wid))
                throw std::runtime_error("reloaded word " + std::to_string(wid) + " differs");
    }
    const std::size_t n = training.size();
    const int count = static_cast<int>(std::min<std::size_t>(n, kRoundTripImages));
    for (int i = 0; i < count; ++i) {
        const std::size_t image = count > 1 ? i * (n - 1) / (count - 1) : 0;
        DBoW2::BowVector expected, fromFile, fromCopy;
        trained.transform(training[image], expected);
        reloaded.transform(training[image], fromFile);
        copied.transform(training[image], fromCopy);
        if (expected.empty() || fromFile != expected || fromCopy != expected)
            throw std::runtime_error("BoW vector of training image " + std::to_string(image) +
                                     " differs after reloading");
    }
    return count;
}

int usage()
{
    std::cerr << "usage: train_brief_vocabulary [--seed N] PATTERN_YML OUT.bin IMAGE_OR_DIR...\n"
                 "  PATTERN_YML  VINS-Fusion's support_files/brief_pattern.yml\n"
                 "  OUT.bin      the vocabulary, in loop_fusion's binary format (k 10, L 6)\n"
                 "  IMAGE_OR_DIR image files, or directories whose image files are used\n"
                 "  --seed N     k-means++ seed (default 1)\n";
    return 1;
}

int run(int argc, char **argv)
{
    int first = 1;
    int seed = 1;
    if (argc > 1 && std::string(argv[1]) == "--seed") {
        char *end = nullptr;
        const long value = argc > 2 ? std::strtol(argv[2], &end, 10) : -1;
        if (argc <= 2 || end == argv[2] || *end != '\0' || value < 0 || value > INT32_MAX) {
            std::cerr << "train_brief_vocabulary: --seed needs an integer in [0, 2^31)\n";
            return usage();
        }
        seed = static_cast<int>(value);
        first = 3;
    }
    if (argc - first < 3)
        return usage();
    const std::string pattern = argv[first], out = argv[first + 1];

    // Before any upstream class draws a number: BRIEF's constructor and k-means++ seed only once.
    DUtils::Random::SeedRandOnce(seed);
    const auto start = std::chrono::steady_clock::now();
    const KeyframeDescriber describer(pattern);

    std::vector<std::vector<Descriptor>> training;
    std::size_t descriptors = 0, skipped = 0;
    for (int a = first + 2; a < argc; ++a) {
        for (const std::string &file : imagesOf(argv[a])) {
            const cv::Mat grey = cv::imread(file, cv::IMREAD_GRAYSCALE);
            if (grey.empty()) {
                std::cerr << "train_brief_vocabulary: skipping unreadable image " << file << "\n";
                ++skipped;
                continue;
            }
            std::vector<Descriptor> described = describer.describe(grey);
            if (described.empty()) {
                std::cerr << "train_brief_vocabulary: skipping " << file << " (no FAST corner)\n";
                ++skipped;
                continue;
            }
            descriptors += described.size();
            training.push_back(std::move(described));
        }
    }
    if (training.empty())
        throw std::runtime_error("no descriptor from any image given");
    std::cout << "train_brief_vocabulary: " << training.size() << " images (" << skipped
              << " skipped), " << descriptors << " descriptors, described in "
              << secondsSince(start) << " s" << std::endl;

    const auto train_start = std::chrono::steady_clock::now();
    BriefVocabulary vocabulary(kBranching, kLevels, DBoW2::TF_IDF, DBoW2::L1_NORM);
    vocabulary.create(training);
    const double train_seconds = secondsSince(train_start);
    vocabulary.saveBin(out);
    std::cout << "train_brief_vocabulary: k " << kBranching << ", L " << kLevels << ", "
              << vocabulary.size() << " words, " << vocabulary.nodeCount() << " nodes, trained in "
              << train_seconds << " s -> " << out << " (" << fs::file_size(out) << " bytes)"
              << std::endl;

    const int checked = checkRoundTrip(vocabulary, out, training);
    std::cout << "train_brief_vocabulary: round trip ok (header, " << vocabulary.size()
              << " words, BoW vectors of " << checked
              << " training images identical after loadBin and a copy); total "
              << secondsSince(start) << " s" << std::endl;
    return 0;
}

} // namespace

int main(int argc, char **argv)
{
    try {
        return run(argc, argv);
    } catch (const std::exception &e) {
        std::cerr << "train_brief_vocabulary: error: " << e.what() << "\n";
    } catch (const std::string &e) { // upstream DBoW2 throws strings
        std::cerr << "train_brief_vocabulary: error: " << e << "\n";
    }
    return 1;
}
