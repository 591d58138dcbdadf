// Trains an ORB vocabulary in ORB-SLAM's text format (the format of ORBvoc.txt) from image
// folders, with ORB-SLAM3's own ORB extractor and DBoW2, so that a run can use a vocabulary
// trained away from its test sequences. Built by integrate.sh against an ORB-SLAM3 tree.
//
//   train_vocabulary OUT.txt K L FEATURES DIR...
//
// K, L: branching factor and depth (ORBvoc.txt: 10 and 6); FEATURES: ORB features per image
// (ORB-SLAM's extractor: scale 1.2, 8 levels, FAST thresholds 20 and 7). Every image file of
// each DIR is used, in name order. Exit status 2 on bad arguments or when no image is read.
#include "ORBVocabulary.h"
#include "ORBextractor.h"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

namespace {

int to_int(const char *text, int low, int high, const char *what)
{
    char *end = nullptr;
    const long value = std::strtol(text, &end, 10);
    if (end == text || *end != '\0' || value < low || value > high) {
        std::cerr << "train_vocabulary: " << what << " must be an integer in [" << low << ", "
                  << high << "], not '" << text << "'\n";
        std::exit(2);
    }
    return static_cast<int>(value);
}

std::vector<std::string> images_of(const std::string &dir)
{
    std::vector<std::string> files;
    for (const char *pattern : {"/*.png", "/*.jpg", "/*.jpeg", "/*.pgm"}) {
        std::vector<cv::String> found;
        cv::glob(dir + pattern, found, false);
        files.insert(files.end(), found.begin(), found.end());
    }
    std::sort(files.begin(), files.end());
    return files;
}

} // namespace

int main(int argc, char **argv)
{
    if (argc < 6) {
        std::cerr << "usage: train_vocabulary OUT.txt K L FEATURES DIR...\n";
        return 2;
    }
    const std::string out = argv[1];
    const int k = to_int(argv[2], 2, 100, "K");
    const int levels = to_int(argv[3], 1, 10, "L");
    const int features = to_int(argv[4], 100, 10000, "FEATURES");
    ORB_SLAM3::ORBextractor extractor(features, 1.2f, 8, 20, 7);

    std::vector<std::vector<cv::Mat>> training;
    std::size_t descriptors = 0;
    for (int a = 5; a < argc; ++a) {
        for (const std::string &file : images_of(argv[a])) {
            const cv::Mat image = cv::imread(file, cv::IMREAD_GRAYSCALE);
            if (image.empty()) {
                std::cerr << "train_vocabulary: skipping unreadable " << file << "\n";
                continue;
            }
            std::vector<cv::KeyPoint> keypoints;
            cv::Mat rows;
            std::vector<int> lapping = {0, 0};
            extractor(image, cv::Mat(), keypoints, rows, lapping);
            std::vector<cv::Mat> one;
            one.reserve(static_cast<std::size_t>(rows.rows));
            for (int r = 0; r < rows.rows; ++r)
                one.push_back(rows.row(r).clone());
            descriptors += one.size();
            training.push_back(std::move(one));
        }
    }
    if (training.empty()) {
        std::cerr << "train_vocabulary: no image read from the given folders\n";
        return 2;
    }
    std::cout << "train_vocabulary: " << training.size() << " images, " << descriptors
              << " descriptors, k " << k << ", L " << levels << std::endl;
    const auto start = std::chrono::steady_clock::now();
    ORB_SLAM3::ORBVocabulary vocabulary(k, levels, DBoW2::TF_IDF, DBoW2::L1_NORM);
    vocabulary.create(training);
    vocabulary.saveToTextFile(out);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << "train_vocabulary: " << vocabulary.size() << " words in " << seconds << " s -> "
              << out << std::endl;
    return 0;
}
