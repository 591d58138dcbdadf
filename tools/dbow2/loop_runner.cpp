// loop_runner: DBoW2 + DLoopDetector (ORB) over the keyframes of a KITTI odometry sequence,
// one CSV row per keyframe, for a side-by-side comparison with `topoloc loops`.
//
//   loop_runner --voc VOCABULARY.yml.gz --sequence SEQ_DIR --out OUT.csv
//               [--keyframe-rate HZ] [--max-frames N] [--alpha A]
//
// SEQ_DIR holds image_0/*.png (file-name order) and times.txt (one timestamp in seconds per
// line). Keyframes are chosen as `topoloc loops --keyframe-rate` does: the first frame (t0),
// then the first frame at or after each due time t0 + k / HZ, k = 1, 2, ... (all frames without
// a rate): HZ keyframes per second on average, 3 of KITTI's 10 Hz being frames 0, 4, 7, 10, ...
// The detector keeps DLoopDetector's default parameters (Parameters(rows, cols)) except
// dislocal = round(10 * HZ) keyframes (100 without a rate: KITTI's 10 Hz) and alpha.
//
// CSV: query_index,frame,status,matched_index,score,ms
//   matched_index: the keyframe the detector matched or proposed (LOOP_DETECTED,
//     NO_GEOMETRICAL_CONSISTENCY, NO_TEMPORAL_CONSISTENCY, NO_GROUPS), else empty.
//   score: the normalised similarity score of that match, s(v_q, v_m) / s(v_q, v_{q-1}), as the
//     detector compares it with alpha; DetectionResult does not carry it, so it is recomputed
//     outside the timed section with the same vocabulary (empty with no match).
//   ms: ORB extraction + detectLoop for the keyframe, wall clock, OpenCV on one thread.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "DLoopDetector.h"
#include "fast_load.h"

namespace fs = std::filesystem;
using Detector = DLoopDetector::TemplatedLoopDetector<DBoW2::FORB::TDescriptor, DBoW2::FORB>;
using Vocabulary = FastLoadVocabulary<DBoW2::FORB::TDescriptor, DBoW2::FORB>;

namespace {

[[noreturn]] void die(const std::string &msg)
{
    std::cerr << "loop_runner: " << msg << "\n";
    std::exit(2);
}

const char *status_name(DLoopDetector::DetectionStatus s)
{
    switch (s) {
    case DLoopDetector::LOOP_DETECTED:
        return "LOOP_DETECTED";
    case DLoopDetector::CLOSE_MATCHES_ONLY:
        return "CLOSE_MATCHES_ONLY";
    case DLoopDetector::NO_DB_RESULTS:
        return "NO_DB_RESULTS";
    case DLoopDetector::LOW_NSS_FACTOR:
        return "LOW_NSS_FACTOR";
    case DLoopDetector::LOW_SCORES:
        return "LOW_SCORES";
    case DLoopDetector::NO_GROUPS:
        return "NO_GROUPS";
    case DLoopDetector::NO_TEMPORAL_CONSISTENCY:
        return "NO_TEMPORAL_CONSISTENCY";
    case DLoopDetector::NO_GEOMETRICAL_CONSISTENCY:
        return "NO_GEOMETRICAL_CONSISTENCY";
    }
    return "UNKNOWN";
}

// Statuses for which DetectionResult::match holds a candidate set during this query.
bool has_candidate(DLoopDetector::DetectionStatus s)
{
    return s == DLoopDetector::LOOP_DETECTED || s == DLoopDetector::NO_GEOMETRICAL_CONSISTENCY ||
           s == DLoopDetector::NO_TEMPORAL_CONSISTENCY || s == DLoopDetector::NO_GROUPS;
}

double parse_double(const std::string &flag, const std::string &v)
{
    char *end = nullptr;
    double x = std::strtod(v.c_str(), &end);
    if (v.empty() || *end != '\0' || !std::isfinite(x))
        die(flag + " needs a number, got '" + v + "'");
    return x;
}

std::vector<double> read_times(const fs::path &path)
{
    std::ifstream in(path);
    if (!in)
        die("cannot read " + path.string());
    std::vector<double> t;
    std::string line;
    size_t n = 0;
    while (std::getline(in, line)) {
        ++n;
        std::istringstream ss(line);
        double x;
        if (!(ss >> x)) {
            if (line.find_first_not_of(" \t\r") == std::string::npos)
                continue;
            die(path.string() + " line " + std::to_string(n) + ": not a number: " + line);
        }
        t.push_back(x);
    }
    return t;
}

double median(std::vector<double> v)
{
    if (v.empty())
        return NAN;
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

} // namespace

int main(int argc, char **argv)
{
    std::string voc_path, seq_dir, out_path;
    double rate = 0.0, alpha = 0.3;
    long max_frames = -1;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc)
                die(a + " needs a value");
            return argv[++i];
        };
        if (a == "--voc")
            voc_path = value();
        else if (a == "--sequence")
            seq_dir = value();
        else if (a == "--out")
            out_path = value();
        else if (a == "--keyframe-rate") {
            rate = parse_double(a, value());
            if (!(rate > 0))
                die("--keyframe-rate must be > 0");
        } else if (a == "--alpha")
            alpha = parse_double(a, value());
        else if (a == "--max-frames") {
            max_frames = std::lround(parse_double(a, value()));
            if (max_frames < 1)
                die("--max-frames must be at least 1");
        } else if (a == "-h" || a == "--help") {
            std::cout << "usage: loop_runner --voc VOC --sequence SEQ_DIR --out OUT.csv "
                         "[--keyframe-rate HZ] [--max-frames N] [--alpha A]\n";
            return 0;
        } else
            die("unknown argument '" + a + "' (see --help)");
    }
    if (voc_path.empty() || seq_dir.empty() || out_path.empty())
        die("--voc, --sequence and --out are required (see --help)");

    // Sequence: image_0/*.png in file-name order, times.txt beside it.
    const fs::path img_dir = fs::path(seq_dir) / "image_0";
    if (!fs::is_directory(img_dir))
        die("no image_0/ folder in " + seq_dir);
    std::vector<fs::path> images;
    for (const auto &e : fs::directory_iterator(img_dir))
        if (e.is_regular_file() && e.path().extension() == ".png")
            images.push_back(e.path());
    std::sort(images.begin(), images.end());
    if (images.empty())
        die("no .png images in " + img_dir.string());
    const std::vector<double> times = read_times(fs::path(seq_dir) / "times.txt");
    if (times.size() < images.size())
        die("times.txt has " + std::to_string(times.size()) + " timestamps for " +
            std::to_string(images.size()) + " images");
    size_t nframes = images.size();
    if (max_frames > 0)
        nframes = std::min(nframes, static_cast<size_t>(max_frames));

    // Keyframes, as `topoloc loops --keyframe-rate` keeps them.
    // Due times t0 + k / HZ: the first frame at or after each is kept (HZ per second on
    // average); `due` numbers the next one, the slack absorbs timestamp rounding.
    std::vector<size_t> keyframes;
    const double slack_s = 1e-6;
    double due = 0.0;
    for (size_t i = 0; i < nframes; ++i) {
        if (rate <= 0) {
            keyframes.push_back(i);
            continue;
        }
        const double periods = (times[i] - times[0]) * rate;
        if (periods >= due - slack_s * rate) {
            keyframes.push_back(i);
            due = std::floor(periods + slack_s * rate) + 1.0;
        }
    }
    const int dislocal = rate > 0 ? static_cast<int>(std::lround(10.0 * rate)) : 100;

    cv::setNumThreads(1);
    cv::Mat first = cv::imread(images[0].string(), cv::IMREAD_GRAYSCALE);
    if (first.empty())
        die("cannot read " + images[0].string());

    Vocabulary voc;
    {
        auto t0 = std::chrono::steady_clock::now();
        try {
            voc.loadFast(voc_path);      // DBoW2's load() format, read in linear time
        } catch (const std::string &e) { // DBoW2 throws strings
            die("cannot load vocabulary " + voc_path + ": " + e);
        } catch (const std::exception &e) {
            die("cannot load vocabulary " + voc_path + ": " + e.what());
        }
        if (voc.empty())
            die("vocabulary " + voc_path + " is empty");
        double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::cerr << "vocabulary: " << voc.size() << " words, k=" << voc.getBranchingFactor()
                  << " L=" << voc.getDepthLevels() << " (loaded in " << s << " s)\n";
    }

    Detector::Parameters params(first.rows, first.cols); // library defaults
    params.dislocal = dislocal;
    params.alpha = static_cast<float>(alpha);
    std::cerr << "sequence " << seq_dir << ": " << nframes << " frames, " << keyframes.size()
              << " keyframes"
              << (rate > 0 ? " at " + std::to_string(rate) + " Hz" : " (all frames)") << "; image "
              << first.cols << "x" << first.rows << "\n"
              << "parameters: use_nss=" << params.use_nss << " alpha=" << params.alpha
              << " k=" << params.k << " geom_check=" << params.geom_check
              << " di_levels=" << params.di_levels << " dislocal=" << params.dislocal
              << " max_db_results=" << params.max_db_results
              << " min_nss_factor=" << params.min_nss_factor
              << " min_matches_per_group=" << params.min_matches_per_group
              << " max_intragroup_gap=" << params.max_intragroup_gap
              << " max_distance_between_groups=" << params.max_distance_between_groups
              << " max_distance_between_queries=" << params.max_distance_between_queries
              << " min_Fpoints=" << params.min_Fpoints
              << " max_reprojection_error=" << params.max_reprojection_error
              << " max_neighbor_ratio=" << params.max_neighbor_ratio << "\n";

    // As the base class: the detector's templated constructor would take a subclass for a database.
    const DBoW2::TemplatedVocabulary<DBoW2::FORB::TDescriptor, DBoW2::FORB> &base_voc = voc;
    Detector detector(base_voc, params);
    detector.allocate(static_cast<int>(keyframes.size()), 1000);
    cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);

    std::ofstream out(out_path);
    if (!out)
        die("cannot write " + out_path);
    out << "query_index,frame,status,matched_index,score,ms\n";

    std::vector<DBoW2::BowVector> bows; // for the recomputed score only (untimed)
    bows.reserve(keyframes.size());
    std::vector<double> ms_all;
    size_t loops = 0;
    for (size_t q = 0; q < keyframes.size(); ++q) {
        const size_t frame = keyframes[q];
        cv::Mat img = q == 0 ? first : cv::imread(images[frame].string(), cv::IMREAD_GRAYSCALE);
        if (img.empty())
            die("cannot read " + images[frame].string());
        if (img.rows != first.rows || img.cols != first.cols)
            die(images[frame].string() + " is not the size of the first image");

        // Timed: ORB extraction + detectLoop.
        auto t0 = std::chrono::steady_clock::now();
        std::vector<cv::KeyPoint> keys;
        cv::Mat desc_mat;
        orb->detectAndCompute(img, cv::noArray(), keys, desc_mat);
        std::vector<DBoW2::FORB::TDescriptor> descs;
        descs.reserve(desc_mat.rows);
        for (int r = 0; r < desc_mat.rows; ++r)
            descs.push_back(desc_mat.row(r));
        DLoopDetector::DetectionResult result;
        result.match = 0;
        detector.detectLoop(keys, descs, result);
        double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                        .count();
        ms_all.push_back(ms);

        // Untimed: the normalised similarity score of the reported match.
        DBoW2::BowVector bow;
        voc.transform(descs, bow);
        bows.push_back(bow);
        std::string matched, score;
        if (has_candidate(result.status)) {
            matched = std::to_string(result.match);
            if (q >= 1 && result.match < q) {
                double prev = voc.score(bow, bows[q - 1]);
                if (prev > 0) {
                    char buf[32];
                    std::snprintf(buf, sizeof buf, "%.6f",
                                  voc.score(bow, bows[result.match]) / prev);
                    score = buf;
                }
            }
        }
        if (result.status == DLoopDetector::LOOP_DETECTED)
            ++loops;
        char msbuf[32];
        std::snprintf(msbuf, sizeof msbuf, "%.3f", ms);
        out << q << ',' << frame << ',' << status_name(result.status) << ',' << matched << ','
            << score << ',' << msbuf << '\n';
        if ((q + 1) % 200 == 0)
            std::cerr << "  " << (q + 1) << "/" << keyframes.size() << " keyframes, " << loops
                      << " loops\n";
    }
    out.close();
    if (!out)
        die("error writing " + out_path);

    std::printf("keyframes %zu\nloops_detected %zu\nalpha %.3f\ndislocal %d\nmedian_ms %.3f\n",
                keyframes.size(), loops, alpha, dislocal, median(ms_all));
    return 0;
}
