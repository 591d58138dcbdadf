// train_vocabulary: a DBoW2 ORB vocabulary (k=10, L=6, TF-IDF weighting, L1 score by default)
// from the ORB-1000 features of every image (.png/.jpg/.jpeg, file-name order) in the given
// folders. Saved with DBoW2's own save() (OpenCV FileStorage: .yml.gz or .yml).
//
//   train_vocabulary OUT.yml.gz FOLDER [FOLDER...] [--k 10] [--L 6]

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "DBoW2.h"

namespace fs = std::filesystem;
using Vocabulary = DBoW2::TemplatedVocabulary<DBoW2::FORB::TDescriptor, DBoW2::FORB>;

[[noreturn]] static void die(const std::string &msg)
{
    std::cerr << "train_vocabulary: " << msg << "\n";
    std::exit(2);
}

int main(int argc, char **argv)
{
    std::string out_path;
    std::vector<std::string> folders;
    int k = 10, L = 6;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--k" || a == "--L") {
            if (i + 1 >= argc)
                die(a + " needs a value");
            int v = std::atoi(argv[++i]);
            if (v < 2 && a == "--k")
                die("--k must be at least 2");
            if (v < 1)
                die("--L must be at least 1");
            (a == "--k" ? k : L) = v;
        } else if (a == "-h" || a == "--help") {
            std::cout << "usage: train_vocabulary OUT.yml.gz FOLDER [FOLDER...] [--k 10] [--L 6]\n";
            return 0;
        } else if (out_path.empty()) {
            out_path = a;
        } else {
            folders.push_back(a);
        }
    }
    if (out_path.empty() || folders.empty())
        die("usage: train_vocabulary OUT.yml.gz FOLDER [FOLDER...]");

    std::vector<fs::path> images;
    for (const auto &folder : folders) {
        if (!fs::is_directory(folder))
            die("not a folder: " + folder);
        std::vector<fs::path> here;
        for (const auto &e : fs::directory_iterator(folder)) {
            std::string ext = e.path().extension().string();
            std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
            if (e.is_regular_file() && (ext == ".png" || ext == ".jpg" || ext == ".jpeg"))
                here.push_back(e.path());
        }
        if (here.empty())
            die("no images in " + folder);
        std::sort(here.begin(), here.end());
        images.insert(images.end(), here.begin(), here.end());
    }

    cv::setNumThreads(1);
    cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
    std::vector<std::vector<DBoW2::FORB::TDescriptor>> features;
    features.reserve(images.size());
    size_t total = 0;
    for (const auto &path : images) {
        cv::Mat img = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
        if (img.empty())
            die("cannot read " + path.string());
        std::vector<cv::KeyPoint> keys;
        cv::Mat desc;
        orb->detectAndCompute(img, cv::noArray(), keys, desc);
        features.emplace_back();
        for (int r = 0; r < desc.rows; ++r)
            features.back().push_back(desc.row(r).clone());
        total += desc.rows;
    }
    std::cerr << images.size() << " images, " << total << " ORB descriptors; training k=" << k
              << " L=" << L << " TF-IDF L1\n";

    auto t0 = std::chrono::steady_clock::now();
    Vocabulary voc(k, L, DBoW2::TF_IDF, DBoW2::L1_NORM);
    voc.create(features);
    double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cerr << "trained in " << s << " s: " << voc << "\n";
    try {
        voc.save(out_path);
    } catch (const std::string &e) {
        die("cannot save " + out_path + ": " + e);
    }
    std::cout << "vocabulary " << out_path << ": " << voc.size() << " words from " << images.size()
              << " images\n";
    return 0;
}
